//! Row-parallel loops on rayon's pool (feature `parallel`), or plain loops without it (and on
//! the calling thread when the pool has one thread: handing work to a single worker only adds
//! its wake-up). Every caller gives each row (or chunk) to exactly one closure call that reads
//! shared inputs and writes only its own output, so results do not depend on the thread count.
//!
//! Plumbing shared by the workspace's crates (terrain-lod runs its rows here too, so that both
//! crates split work the same way), not API: hidden from the docs and free to change in any
//! release.

/// Whether to hand work to rayon: the pool has more than one thread.
#[cfg(feature = "parallel")]
#[inline]
fn parallel() -> bool {
    rayon::current_num_threads() > 1
}

/// Calls `f(index, chunk)` for every `chunk_len`-long chunk of `data` (the last may be
/// shorter), in parallel when the `parallel` feature is on and the pool has several threads.
pub fn for_each_chunk<T: Send>(
    data: &mut [T],
    chunk_len: usize,
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    let chunk_len = chunk_len.max(1);
    #[cfg(feature = "parallel")]
    if parallel() {
        use rayon::prelude::*;
        data.par_chunks_mut(chunk_len)
            .enumerate()
            .for_each(|(i, c)| f(i, c));
        return;
    }
    data.chunks_mut(chunk_len)
        .enumerate()
        .for_each(|(i, c)| f(i, c));
}

/// Like [`for_each_chunk`] over two slices cut into chunks of their own lengths
/// (`a_len` and `b_len` per chunk index).
pub fn for_each_chunk2<A: Send, B: Send>(
    a: &mut [A],
    a_len: usize,
    b: &mut [B],
    b_len: usize,
    f: impl Fn(usize, &mut [A], &mut [B]) + Sync + Send,
) {
    let (a_len, b_len) = (a_len.max(1), b_len.max(1));
    #[cfg(feature = "parallel")]
    if parallel() {
        use rayon::prelude::*;
        a.par_chunks_mut(a_len)
            .zip(b.par_chunks_mut(b_len))
            .enumerate()
            .for_each(|(i, (x, y))| f(i, x, y));
        return;
    }
    a.chunks_mut(a_len)
        .zip(b.chunks_mut(b_len))
        .enumerate()
        .for_each(|(i, (x, y))| f(i, x, y));
}

/// The sum of `f` over `items` (u64 addition is associative, so any split gives the same sum).
pub fn map_sum<I: Sync>(items: &[I], f: impl Fn(&I) -> u64 + Sync + Send) -> u64 {
    #[cfg(feature = "parallel")]
    if parallel() {
        use rayon::prelude::*;
        return items.par_iter().map(f).sum();
    }
    items.iter().map(f).sum()
}

/// Like [`for_each_chunk`], with a scratch value made by `init` for each piece of work rayon
/// splits off (once when sequential) and lent to every call of `f` in it: per-row buffers
/// without an allocation per row. `f` must not let a chunk's result depend on what an earlier
/// chunk left in the scratch.
pub fn for_each_chunk_init<T: Send, S>(
    data: &mut [T],
    chunk_len: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) + Sync + Send,
) {
    let chunk_len = chunk_len.max(1);
    #[cfg(feature = "parallel")]
    if parallel() {
        use rayon::prelude::*;
        data.par_chunks_mut(chunk_len)
            .enumerate()
            .for_each_init(init, |s, (i, c)| f(s, i, c));
        return;
    }
    let mut s = init();
    data.chunks_mut(chunk_len)
        .enumerate()
        .for_each(|(i, c)| f(&mut s, i, c));
}

/// Calls `f(index, item)` for every item, in parallel when the `parallel` feature is on and the pool has several threads.
pub fn for_each_item<T: Send>(items: Vec<T>, f: impl Fn(usize, T) + Sync + Send) {
    #[cfg(feature = "parallel")]
    if parallel() {
        use rayon::prelude::*;
        items.into_par_iter().enumerate().for_each(|(i, t)| f(i, t));
        return;
    }
    items.into_iter().enumerate().for_each(|(i, t)| f(i, t));
}

/// `f` of every item, in order, in parallel when the `parallel` feature is on and the pool has
/// several threads.
pub fn map_collect<I: Sync, O: Send>(items: &[I], f: impl Fn(&I) -> O + Sync + Send) -> Vec<O> {
    #[cfg(feature = "parallel")]
    if parallel() {
        use rayon::prelude::*;
        return items.par_iter().map(f).collect();
    }
    items.iter().map(f).collect()
}
