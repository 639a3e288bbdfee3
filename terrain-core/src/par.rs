//! Row-parallel loops on rayon's pool (feature `parallel`), or plain loops without it. Every
//! caller gives each row (or chunk) to exactly one closure call that reads shared inputs and
//! writes only its own output, so results do not depend on the thread count.

/// Calls `f(index, chunk)` for every `chunk_len`-long chunk of `data` (the last may be
/// shorter), in parallel when the `parallel` feature is on.
pub(crate) fn for_each_chunk<T: Send>(
    data: &mut [T],
    chunk_len: usize,
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    let chunk_len = chunk_len.max(1);
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        data.par_chunks_mut(chunk_len)
            .enumerate()
            .for_each(|(i, c)| f(i, c));
    }
    #[cfg(not(feature = "parallel"))]
    {
        data.chunks_mut(chunk_len)
            .enumerate()
            .for_each(|(i, c)| f(i, c));
    }
}

/// Like [`for_each_chunk`] over two slices cut into chunks of their own lengths
/// (`a_len` and `b_len` per chunk index).
pub(crate) fn for_each_chunk2<A: Send, B: Send>(
    a: &mut [A],
    a_len: usize,
    b: &mut [B],
    b_len: usize,
    f: impl Fn(usize, &mut [A], &mut [B]) + Sync + Send,
) {
    let (a_len, b_len) = (a_len.max(1), b_len.max(1));
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        a.par_chunks_mut(a_len)
            .zip(b.par_chunks_mut(b_len))
            .enumerate()
            .for_each(|(i, (x, y))| f(i, x, y));
    }
    #[cfg(not(feature = "parallel"))]
    {
        a.chunks_mut(a_len)
            .zip(b.chunks_mut(b_len))
            .enumerate()
            .for_each(|(i, (x, y))| f(i, x, y));
    }
}

/// The sum of `f` over `items` (u64 addition is associative, so any split gives the same sum).
pub(crate) fn map_sum<I: Sync>(items: &[I], f: impl Fn(&I) -> u64 + Sync + Send) -> u64 {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter().map(f).sum()
    }
    #[cfg(not(feature = "parallel"))]
    {
        items.iter().map(f).sum()
    }
}

/// Like [`for_each_chunk`], with a scratch value made by `init` for each piece of work rayon
/// splits off (once without the `parallel` feature) and lent to every call of `f` in it:
/// per-row buffers without an allocation per row. `f` must not let a chunk's result depend on
/// what an earlier chunk left in the scratch.
pub(crate) fn for_each_chunk_init<T: Send, S>(
    data: &mut [T],
    chunk_len: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) + Sync + Send,
) {
    let chunk_len = chunk_len.max(1);
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        data.par_chunks_mut(chunk_len)
            .enumerate()
            .for_each_init(init, |s, (i, c)| f(s, i, c));
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut s = init();
        data.chunks_mut(chunk_len)
            .enumerate()
            .for_each(|(i, c)| f(&mut s, i, c));
    }
}

/// Calls `f(index, item)` for every item, in parallel when the `parallel` feature is on.
pub(crate) fn for_each_item<T: Send>(items: Vec<T>, f: impl Fn(usize, T) + Sync + Send) {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.into_par_iter().enumerate().for_each(|(i, t)| f(i, t));
    }
    #[cfg(not(feature = "parallel"))]
    {
        items.into_iter().enumerate().for_each(|(i, t)| f(i, t));
    }
}
