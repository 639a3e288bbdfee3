//! Target `manifest`: `Manifest::from_json`, `read_manifest` and the store keys, from valid
//! manifests, edited field values, damaged text and random bytes.

use crate::worlds::{MemStore, random_manifest};
use std::sync::Arc;
use terrain_cache::manifest::{MANIFEST_KEY, bounds_key, parse_tile_key, tile_key};
use terrain_cache::store::check_key;
use terrain_cache::world::read_manifest;
use terrain_cache::{Layer, Manifest, TileFormat, TileId, TileStore, World};
use terrain_test_support::fuzz::{Case, Class, Rng};

/// Checks a manifest that parsed: it validates, and its queries answer for any level and tile
/// without panicking.
fn exercise_manifest(m: &Manifest, rng: &mut Rng) -> Result<(), String> {
    m.validate()
        .map_err(|e| format!("from_json accepted a manifest that does not validate: {e}"))?;
    let _ = (m.max_levels(), m.extent_m());
    for level in [
        0,
        1,
        m.levels - 1,
        m.levels,
        31,
        32,
        u32::MAX,
        rng.next_u32(),
    ] {
        let _ = (m.level_size(level), m.tiles_at(level));
        for layer in [Layer::Height, Layer::Detail] {
            let _ = (
                m.layer_tiles(layer, level),
                m.tile_extent_m(layer, level),
                m.tiles_of(layer, level).take(3).count(),
            );
            let id = TileId::new(level, rng.u32_edge(), rng.u32_edge());
            let _ = m.check_tile(layer, id);
        }
    }
    for layer in [Layer::Height, Layer::Detail] {
        let _ = (
            m.layer_levels(layer),
            m.layer_tile_size(layer),
            m.layer_fill(layer),
        );
    }
    let world = World::create(Arc::new(MemStore::default()), *m)
        .map_err(|e| format!("a valid manifest could not create a world: {e}"))?;
    let _ = world.max_tile_file_bytes(Layer::Height);
    let _ = world.max_tile_file_bytes(Layer::Detail);
    Ok(())
}

/// Random valid manifests survive `to_json` / `from_json` unchanged.
fn manifest_roundtrip(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let m = random_manifest(rng);
    let back = Manifest::from_json(&m.to_json())
        .map_err(|e| format!("a valid manifest did not parse back: {e}\n{}", m.to_json()))?;
    if back != m {
        return Err(format!("{m:?} parsed back as {back:?}"));
    }
    exercise_manifest(&back, rng)
}

/// A JSON value that code reading numbers, strings and objects tends to get wrong.
fn edge_json(rng: &mut Rng) -> serde_json::Value {
    use serde_json::json;
    match rng.below(12) {
        0 => json!(rng.u32_edge()),
        1 => json!(-(rng.below(3) as i64) - 1),
        2 => json!(u64::MAX),
        3 => json!(i64::MIN),
        4 => json!(rng.f32_edge()),
        5 => json!(rng.f32_bits()),
        6 => serde_json::from_str("1e39").unwrap(),
        7 => json!("repeat"),
        8 => json!(null),
        9 => json!([rng.u32_edge(), rng.u32_edge()]),
        10 => json!({ "tile_size": 16 }),
        _ => json!(rng.next_u64() as f64 * 1e-10),
    }
}

/// A valid manifest with one or more fields (or detail fields) set to edge values, removed, or
/// joined by unknown ones.
fn manifest_fields(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let m = random_manifest(rng);
    let mut v: serde_json::Value = serde_json::from_str(&m.to_json()).unwrap();
    for _ in 0..rng.range_u32(1, 3) {
        let detail = rng.chance(1, 3) && v.get("detail").is_some_and(|d| d.is_object());
        let Some(obj) = (if detail {
            v.get_mut("detail")
        } else {
            Some(&mut v)
        })
        .and_then(|o| o.as_object_mut()) else {
            continue;
        };
        let keys: Vec<String> = obj.keys().cloned().collect();
        // An earlier edit may have emptied the object (or replaced the detail object).
        let Some(key) = keys.get(rng.index(keys.len())).cloned() else {
            obj.insert("tile_size".into(), edge_json(rng));
            continue;
        };
        match rng.below(6) {
            0 => {
                obj.remove(&key);
            }
            1 => {
                obj.insert("unknown_field".into(), edge_json(rng));
            }
            2 if key == "world_size" || key == "tiles" => {
                obj.insert(key, serde_json::json!([rng.u32_edge(), rng.u32_edge()]));
            }
            3 if key == "wrap" => {
                obj.insert(
                    key,
                    serde_json::json!(rng.pick(&["Repeat", "clamp ", "", "mirror"])),
                );
            }
            _ => {
                obj.insert(key, edge_json(rng));
            }
        }
    }
    let text = v.to_string();
    match Manifest::from_json(&text) {
        Ok(m) => exercise_manifest(&m, rng),
        Err(_) => Ok(()),
    }
}

/// Byte-level damage to the JSON text (truncation, flips, inserted characters), read through
/// a store so that text that is not UTF-8 takes the store path.
fn manifest_text(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let m = random_manifest(rng);
    let mut bytes = m.to_json().into_bytes();
    match rng.below(4) {
        0 => {
            let n = bytes.len();
            bytes.truncate(rng.index(n));
        }
        1 => rng.flip_bits(&mut bytes),
        2 => {
            for _ in 0..rng.range_u32(1, 4) {
                let at = rng.index(bytes.len() + 1);
                let c = rng.pick(b"{}[]\",:-+.eE0123456789 \\\0\xff");
                bytes.insert(at, c);
            }
        }
        _ => {
            // A number replaced by a long run of digits.
            if let Some(at) = bytes.iter().position(u8::is_ascii_digit) {
                let n = rng.range_usize(20, 400);
                bytes.splice(at..at + 1, std::iter::repeat_n(b'9', n));
            }
        }
    }
    let store = MemStore::default();
    store
        .write(MANIFEST_KEY, &bytes)
        .map_err(|e| e.to_string())?;
    match read_manifest(&store) {
        Ok(m) => exercise_manifest(&m, rng),
        Err(_) => Ok(()),
    }
}

/// Random bytes and random JSON-ish text as a manifest; missing and oversized manifests.
fn manifest_random(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let store = MemStore::default();
    match rng.below(4) {
        0 => {
            let n = rng.range_usize(0, 600);
            store
                .write(MANIFEST_KEY, &rng.bytes(n))
                .map_err(|e| e.to_string())?;
        }
        1 => {
            let n = rng.range_usize(0, 300);
            let text: String = (0..n)
                .map(|_| char::from(rng.pick(b"{}[]\",:-.e0123456789 abcdefghijklmnopqrstuvwxyz_")))
                .collect();
            store
                .write(MANIFEST_KEY, text.as_bytes())
                .map_err(|e| e.to_string())?;
        }
        2 => {
            let mut big = m_json_padded(rng);
            big.extend(std::iter::repeat_n(b' ', 70_000));
            store.write(MANIFEST_KEY, &big).map_err(|e| e.to_string())?;
        }
        _ => {}
    }
    match read_manifest(&store) {
        Ok(m) => exercise_manifest(&m, rng),
        Err(_) => Ok(()),
    }
}

fn m_json_padded(rng: &mut Rng) -> Vec<u8> {
    random_manifest(rng).to_json().into_bytes()
}

/// Tile keys: every id's key parses back to it; random and damaged keys never panic the key
/// parser or the store's key check, and a key that parses is one `tile_key` writes.
fn keys(_: &(), case: &mut Case) -> Result<(), String> {
    let rng = &mut case.rng;
    let layer = if rng.chance(1, 2) {
        Layer::Height
    } else {
        Layer::Detail
    };
    let id = TileId::new(
        rng.range_u32(0, 255),
        rng.range_u32(0, 65535),
        rng.range_u32(0, 65535),
    );
    let format = if rng.chance(1, 2) {
        TileFormat::Tile
    } else {
        TileFormat::Png
    };
    let key = tile_key(layer, id, format);
    if parse_tile_key(&key) != Some((layer, id)) {
        return Err(format!("{key} did not parse back to {layer:?} {id}"));
    }
    check_key(&key).map_err(|e| format!("{key} is not a valid store key: {e}"))?;
    let _ = bounds_key(layer, rng.next_u32());
    let mut bytes = key.into_bytes();
    match rng.below(4) {
        0 => rng.flip_bits(&mut bytes),
        1 => {
            let n = bytes.len();
            bytes.truncate(rng.index(n + 1));
        }
        2 => {
            let at = rng.index(bytes.len() + 1);
            let c = rng.pick(b"/.\\\0-xX\xc3\xa9");
            bytes.insert(at, c);
        }
        _ => {
            let n = rng.range_usize(0, 40);
            bytes = rng.bytes(n);
        }
    }
    let text = String::from_utf8_lossy(&bytes);
    if let Some((l, i)) = parse_tile_key(&text)
        && [TileFormat::Tile, TileFormat::Png]
            .iter()
            .all(|&f| tile_key(l, i, f) != text)
    {
        return Err(format!(
            "{text:?} parsed as {l:?} {i}, which is written {} or {}",
            tile_key(l, i, TileFormat::Tile),
            tile_key(l, i, TileFormat::Png)
        ));
    }
    let _ = check_key(&text);
    Ok(())
}

/// The target's classes, in the order they run.
pub(crate) fn classes() -> Vec<Class<()>> {
    fn c(name: &'static str, f: fn(&(), &mut Case) -> Result<(), String>) -> Class<()> {
        Class { name, run: f }
    }
    vec![
        c("valid_roundtrip", manifest_roundtrip),
        c("field_values", manifest_fields),
        c("text_damage", manifest_text),
        c("random_bytes", manifest_random),
        c("tile_keys", keys),
    ]
}
