//! Helpers of the crate's unit tests.

/// f32 arithmetic on a handful of values: hand-computed results hold to a few ulps (relative above 1).
pub const TOL: f32 = 1e-5;

/// `actual` equals the hand-computed `expected` entry by entry within [`TOL`] (relative above 1).
pub fn assert_close(what: &str, actual: &[f32], expected: &[f32]) {
    assert_eq!(actual.len(), expected.len(), "{what}: {actual:?} against {expected:?}");
    for (a, e) in actual.iter().zip(expected) {
        assert!((a - e).abs() <= TOL * e.abs().max(1.0), "{what}: {actual:?}, expected {expected:?}");
    }
}
