// Packed texels (terrain-gpu's `resources::packing`): `bits` bits per texel (8, 16 or 32), so
// 32 / bits texels ("lanes") per u32 word. Texel x of a row sits in word x / lanes at bit
// (x % lanes) * bits, and each row starts on a whole word (the last one padded with zeros), so
// a word never holds texels of two rows.
//
// Writers own whole words: an invocation that changes texels of a word reads the word, changes
// its lanes and writes it back, and no other invocation of the dispatch touches that word, so
// packing needs no atomics and has no races (`packed_group` hands out the words).

fn packed_pitch(width: u32, bits: u32) -> u32 {
    let lanes = 32u / bits;
    return (width + lanes - 1u) / lanes;
}

// The word of texel (x, y) of a map `width` texels wide.
fn packed_index(x: u32, y: u32, width: u32, bits: u32) -> u32 {
    return y * packed_pitch(width, bits) + x / (32u / bits);
}

// Texel x's value in its word.
fn packed_get(word: u32, x: u32, bits: u32) -> u32 {
    let shift = (x % (32u / bits)) * bits;
    return (word >> shift) & (0xffffffffu >> (32u - bits));
}

// The word with texel x's lanes replaced by `value` (already within `bits` bits).
fn packed_set(word: u32, x: u32, bits: u32, value: u32) -> u32 {
    let shift = (x % (32u / bits)) * bits;
    let mask = (0xffffffffu >> (32u - bits)) << shift;
    return (word & ~mask) | ((value << shift) & mask);
}

// The words a run of columns of one row touches, as a writer's invocations take them: columns
// are counted from `start`, in coordinates made non-negative by a multiple of the map's width
// (column c is map column c % width), and split at word edges and at the map's wrap. Group i
// of the run is its i-th word: `word` is that word's index within the row and `first` the
// column (same coordinates) of the word's lane 0. terrain-gpu's `packing::word_groups` counts
// the groups of a run.
struct WordGroup {
    word: u32,
    first: u32,
}

fn packed_group(start: u32, i: u32, width: u32, bits: u32) -> WordGroup {
    let lanes = 32u / bits;
    let pitch = packed_pitch(width, bits);
    let g = (start / width) * pitch + (start % width) / lanes + i;
    let m = g % pitch;
    return WordGroup(m, (g / pitch) * width + m * lanes);
}
