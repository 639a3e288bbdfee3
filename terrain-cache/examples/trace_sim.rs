//! Prints the trace simulator's comparison of tile policies (frustum with margin, band regions,
//! spherical distance, LRU on demand, Belady's MIN) on four camera paths.
//!
//! `cargo run -p terrain-cache --release --example trace_sim`

fn main() {
    let cfg = terrain_cache::SimConfig::default();
    let (_, table) = terrain_cache::comparison_table(&cfg);
    print!("{table}");
}
