//! The on-disk SDF cache, addressed by content: an entry's name is the SHA-256 of everything the bake
//! depends on (this format's version, the mesh's positions and triangles as little-endian bytes, the
//! resolution and the margin's bits), so a changed mesh or parameter can never hit a stale entry, and no
//! index file has to be kept consistent.
//!
//! # File format (`<64 hex digits>.sdf`, little-endian)
//! | offset | size | field |
//! |-------:|-----:|-------|
//! | 0  | 8  | magic `FRS-SDF\n` |
//! | 8  | 4  | format version (u32, [`FORMAT_VERSION`]) |
//! | 12 | 12 | dims (3 x u32) |
//! | 24 | 12 | origin [m] (3 x f32) |
//! | 36 | 4  | spacing [m] (f32) |
//! | 40 | 8  | value count (u64) = dims.x * dims.y * dims.z |
//! | 48 | 32 | SHA-256 of bytes 0..48 followed by the payload |
//! | 80 | 4 * count | values (f32), index x + dims.x * (y + dims.y * z) |
//!
//! Entries are written only through [`crate::fsutil::write_atomic`] (temporary file, fsync, rename), so a
//! process killed while baking or writing leaves either no entry or a complete one; its temporary file
//! (`.<name>.<pid>.<n>.tmp`) is never read as an entry. A file that fails to parse or whose checksum does
//! not match is treated as a miss: logged, rebaked, overwritten; never returned.

use super::bake::{bake, layout, BakeParams};
use super::SdfGrid;
use crate::error::{EngineError, Result};
use crate::mesh::TriMesh;
use glam::{UVec3, Vec3};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// Version of the file layout *and* of the baking algorithm: bump it when either changes, so old entries
/// are never hit again.
pub const FORMAT_VERSION: u32 = 1;

/// First bytes of every cache file.
pub const MAGIC: [u8; 8] = *b"FRS-SDF\n";

/// Extension of cache entries.
pub const ENTRY_EXTENSION: &str = "sdf";

const HEADER_BYTES: usize = 80;
const CHECKSUM_AT: usize = 48;

/// A directory of baked SDFs.
#[derive(Clone, Debug)]
pub struct SdfCache {
    dir: PathBuf,
    /// Grids handed out by [`get_or_bake_shared`](Self::get_or_bake_shared), by entry key, while anyone
    /// holds them (shared by clones of this cache).
    loaded: std::sync::Arc<std::sync::Mutex<std::collections::HashMap<String, std::sync::Weak<SdfGrid>>>>,
}

impl SdfCache {
    /// A cache in `dir` (created on the first write).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        SdfCache { dir: dir.into(), loaded: Default::default() }
    }

    /// `$FACTORY_CACHE_DIR` if set (used as the SDF directory itself), else `$HOME/.cache/factory-rs/sdf`,
    /// else `<temp dir>/factory-rs/sdf`.
    pub fn default_dir() -> PathBuf {
        if let Some(dir) = std::env::var_os("FACTORY_CACHE_DIR").filter(|d| !d.is_empty()) {
            return PathBuf::from(dir);
        }
        match std::env::var_os("HOME").filter(|d| !d.is_empty()) {
            Some(home) => PathBuf::from(home).join(".cache").join("factory-rs").join("sdf"),
            None => std::env::temp_dir().join("factory-rs").join("sdf"),
        }
    }

    /// The cache's directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The content key of a bake: 64 lowercase hex digits.
    pub fn key(mesh: &TriMesh, params: &BakeParams) -> String {
        let mut h = Sha256::new();
        h.update(b"factory-rs sdf");
        h.update(FORMAT_VERSION.to_le_bytes());
        h.update((mesh.positions.len() as u64).to_le_bytes());
        let mut buf = Vec::with_capacity(mesh.positions.len() * 12);
        for p in &mesh.positions {
            for c in p.to_array() {
                buf.extend_from_slice(&c.to_le_bytes());
            }
        }
        h.update(&buf);
        buf.clear();
        h.update((mesh.triangles.len() as u64).to_le_bytes());
        for t in &mesh.triangles {
            for i in t {
                buf.extend_from_slice(&i.to_le_bytes());
            }
        }
        h.update(&buf);
        h.update(params.resolution.to_le_bytes());
        h.update(params.margin.to_bits().to_le_bytes());
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Where the entry for this bake lives (whether or not it exists).
    pub fn entry_path(&self, mesh: &TriMesh, params: &BakeParams) -> PathBuf {
        self.key_path(&Self::key(mesh, params))
    }

    fn key_path(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.{ENTRY_EXTENSION}"))
    }

    /// Whether a file name is a cache entry's (temporary files of interrupted writes are not).
    pub fn is_entry_name(name: &str) -> bool {
        name.strip_suffix(&format!(".{ENTRY_EXTENSION}")).is_some_and(|stem| {
            stem.len() == 64 && stem.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
        })
    }

    /// The entries present in the directory (none if it does not exist).
    pub fn entries(&self) -> Result<Vec<PathBuf>> {
        let rd = match std::fs::read_dir(&self.dir) {
            Ok(rd) => rd,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(EngineError::io(&self.dir, e)),
        };
        let mut out = Vec::new();
        for entry in rd {
            let entry = entry.map_err(|e| EngineError::io(&self.dir, e))?;
            if entry.file_name().to_str().is_some_and(Self::is_entry_name) {
                out.push(entry.path());
            }
        }
        out.sort();
        Ok(out)
    }

    /// As [`get_or_bake`](Self::get_or_bake), but every caller asking for the same mesh and parameters while
    /// an earlier result is still alive gets that same grid (one allocation, and one upload: the contact
    /// model uploads a grid once per `Arc`). Pairs built from one mesh, as in a pile of identical parts,
    /// share their SDF this way.
    pub fn get_or_bake_shared(&self, mesh: &TriMesh, params: &BakeParams) -> Result<std::sync::Arc<SdfGrid>> {
        let key = Self::key(mesh, params);
        if let Some(grid) = self.loaded.lock().unwrap_or_else(|e| e.into_inner()).get(&key).and_then(|w| w.upgrade()) {
            return Ok(grid);
        }
        let grid = std::sync::Arc::new(self.get_or_bake_at(&self.key_path(&key), mesh, params)?);
        let mut loaded = self.loaded.lock().unwrap_or_else(|e| e.into_inner());
        loaded.retain(|_, w| w.strong_count() > 0);
        // Another thread may have loaded it meanwhile: keep the first, so all callers share one grid.
        if let Some(first) = loaded.get(&key).and_then(|w| w.upgrade()) {
            return Ok(first);
        }
        loaded.insert(key, std::sync::Arc::downgrade(&grid));
        Ok(grid)
    }

    /// The cached SDF of this bake, or a fresh bake stored for next time. An unreadable, corrupt or
    /// mismatching entry is logged and replaced. Failing to store the result is logged, not returned.
    pub fn get_or_bake(&self, mesh: &TriMesh, params: &BakeParams) -> Result<SdfGrid> {
        self.get_or_bake_at(&self.entry_path(mesh, params), mesh, params)
    }

    /// [`get_or_bake`](Self::get_or_bake) with the entry's path already known (hashing a mesh is not free).
    fn get_or_bake_at(&self, path: &Path, mesh: &TriMesh, params: &BakeParams) -> Result<SdfGrid> {
        // Validates the parameters and the memory limit even on a hit, and says what a hit must look like.
        let expect = layout(mesh, params)?;
        match load(path) {
            Ok(grid) if grid.dims == expect.dims && grid.origin == expect.origin && grid.spacing == expect.spacing => {
                log::debug!("SDF cache hit: {}", path.display());
                return Ok(grid);
            }
            Ok(grid) => log::warn!(
                "SDF cache entry {} holds a {} grid at {} spaced {}, not the expected {} at {} spaced {}; rebaking",
                path.display(),
                grid.dims,
                grid.origin,
                grid.spacing,
                expect.dims,
                expect.origin,
                expect.spacing
            ),
            Err(EngineError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => log::warn!("SDF cache entry unusable, rebaking: {e}"),
        }
        let grid = bake(mesh, params)?;
        if let Err(e) = save(path, &grid) {
            log::warn!("SDF cache: could not store the bake: {e}");
        }
        Ok(grid)
    }
}

fn header(grid: &SdfGrid) -> [u8; CHECKSUM_AT] {
    let mut h = [0u8; CHECKSUM_AT];
    h[0..8].copy_from_slice(&MAGIC);
    h[8..12].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    for (a, (d, o)) in grid.dims.to_array().into_iter().zip(grid.origin.to_array()).enumerate() {
        h[12 + 4 * a..16 + 4 * a].copy_from_slice(&d.to_le_bytes());
        h[24 + 4 * a..28 + 4 * a].copy_from_slice(&o.to_le_bytes());
    }
    h[36..40].copy_from_slice(&grid.spacing.to_le_bytes());
    h[40..48].copy_from_slice(&(grid.values.len() as u64).to_le_bytes());
    h
}

fn checksum(head: &[u8], payload: &[u8]) -> [u8; 32] {
    let mut h = Sha256::new();
    h.update(head);
    h.update(payload);
    h.finalize().into()
}

/// The file bytes of a grid.
pub fn encode(grid: &SdfGrid) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(HEADER_BYTES + 4 * grid.values.len());
    bytes.extend_from_slice(&header(grid));
    bytes.extend_from_slice(&[0u8; 32]);
    for v in &grid.values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let sum = checksum(&bytes[..CHECKSUM_AT], &bytes[HEADER_BYTES..]);
    bytes[CHECKSUM_AT..HEADER_BYTES].copy_from_slice(&sum);
    bytes
}

/// Parses and validates file bytes; `path` is only used in errors.
pub fn decode(bytes: &[u8], path: &Path) -> Result<SdfGrid> {
    let bad = |message: String| EngineError::Asset {
        path: path.to_path_buf(),
        message: format!("not a valid SDF cache file: {message}"),
    };
    if bytes.len() < HEADER_BYTES {
        return Err(bad(format!("{} bytes, shorter than the {HEADER_BYTES}-byte header", bytes.len())));
    }
    if bytes[0..8] != MAGIC {
        return Err(bad("wrong magic".into()));
    }
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let version = u32_at(8);
    if version != FORMAT_VERSION {
        return Err(bad(format!("format version {version}, this build reads {FORMAT_VERSION}")));
    }
    let dims = UVec3::new(u32_at(12), u32_at(16), u32_at(20));
    let origin = Vec3::new(f32_at(24), f32_at(28), f32_at(32));
    let spacing = f32_at(36);
    let count = u64::from_le_bytes(bytes[40..48].try_into().unwrap());
    if dims.min_element() < 2 {
        return Err(bad(format!("dims {dims}: every axis needs at least 2 samples")));
    }
    let product = dims.x as u64 * dims.y as u64 * dims.z as u64;
    if count != product || product > u32::MAX as u64 {
        return Err(bad(format!("value count {count} does not match dims {dims}")));
    }
    let payload = &bytes[HEADER_BYTES..];
    if payload.len() as u64 != 4 * count {
        return Err(bad(format!("{} payload bytes, expected {} (truncated or padded)", payload.len(), 4 * count)));
    }
    if checksum(&bytes[..CHECKSUM_AT], payload) != bytes[CHECKSUM_AT..HEADER_BYTES] {
        return Err(bad("checksum mismatch (corrupted)".into()));
    }
    if !origin.is_finite() || !(spacing.is_finite() && spacing > 0.0) {
        return Err(bad(format!("origin {origin} / spacing {spacing} not finite and positive")));
    }
    let values: Vec<f32> = payload.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!("value {i} is not finite")));
    }
    Ok(SdfGrid { origin, spacing, dims, values })
}

/// Reads and validates a cache file.
pub fn load(path: &Path) -> Result<SdfGrid> {
    let bytes = std::fs::read(path).map_err(|e| EngineError::io(path, e))?;
    decode(&bytes, path)
}

/// Writes a grid as a cache file, atomically.
pub fn save(path: &Path, grid: &SdfGrid) -> Result<()> {
    let expected = grid.dims.x as u64 * grid.dims.y as u64 * grid.dims.z as u64;
    if grid.values.len() as u64 != expected || grid.dims.min_element() < 2 {
        return Err(EngineError::Asset {
            path: path.to_path_buf(),
            message: format!("refusing to save an SDF with dims {} and {} values", grid.dims, grid.values.len()),
        });
    }
    crate::fsutil::write_atomic(path, &encode(grid))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> SdfGrid {
        SdfGrid {
            origin: Vec3::new(-1.0, 0.5, 2.0),
            spacing: 0.25,
            dims: UVec3::new(2, 3, 4),
            values: (0..24).map(|i| i as f32 * 0.5 - 3.0).collect(),
        }
    }

    #[test]
    fn encode_decode_round_trip_and_every_flipped_byte_is_caught() {
        let g = grid();
        let bytes = encode(&g);
        assert_eq!(bytes.len(), HEADER_BYTES + 4 * 24);
        assert_eq!(decode(&bytes, Path::new("x")).unwrap(), g);
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x10;
            assert!(decode(&b, Path::new("x")).is_err(), "flipping byte {i} went unnoticed");
        }
        for len in [0, 10, HEADER_BYTES, bytes.len() - 1] {
            assert!(decode(&bytes[..len], Path::new("x")).is_err(), "truncation to {len}");
        }
    }

    #[test]
    fn entry_names() {
        let name = format!("{}.sdf", "0123456789abcdef".repeat(4));
        assert!(SdfCache::is_entry_name(&name));
        assert!(!SdfCache::is_entry_name(&format!(".{name}.123.0.tmp")));
        assert!(!SdfCache::is_entry_name("abc.sdf"));
    }
}
