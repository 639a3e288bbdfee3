// Granular penetration pass (placeholder, being written).
@compute @workgroup_size(1, 1, 1)
fn main() {}
