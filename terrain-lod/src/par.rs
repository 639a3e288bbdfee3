//! Row-parallel loops on rayon's pool (feature `parallel`), or plain loops without it. Each
//! row goes to exactly one closure call that reads shared inputs and writes only its own row,
//! so results do not depend on the thread count.

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

/// `f` of every item, in order, in parallel when the `parallel` feature is on.
pub(crate) fn map_collect<I: Sync, O: Send>(
    items: &[I],
    f: impl Fn(&I) -> O + Sync + Send,
) -> Vec<O> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        items.iter().map(f).collect()
    }
}
