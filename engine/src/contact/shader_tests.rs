//! Every contact shader, at the smallest, default and largest patch budget, parses and validates with naga
//! (no GPU needed).

use super::generate::{shader_source, GENERATE_WGSL};
use super::merge::MERGE_WGSL;
use super::normals::NORMALS_WGSL;

pub(crate) fn validate(src: &str) -> Result<(), String> {
    let module = naga::front::wgsl::parse_str(src).map_err(|e| e.emit_to_string(src))?;
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
        .validate(&module)
        .map(|_| ())
        .map_err(|e| format!("{e:?}"))
}

#[test]
fn contact_shaders_validate_with_naga() {
    for max_patches in [16, 64, 256] {
        for (name, wgsl) in [
            ("generate", GENERATE_WGSL),
            ("merge", MERGE_WGSL),
            ("normals", NORMALS_WGSL),
            ("solver", crate::solver::gpu::SOLVER_WGSL),
        ] {
            for revolved in [false, true] {
                let src = shader_source(wgsl, max_patches, super::generate::SdfKinds { revolved });
                if let Err(e) = validate(&src) {
                    panic!("{name}.wgsl with max_patches = {max_patches}, revolved {revolved}:\n{e}");
                }
            }
        }
    }
}

#[test]
fn naga_rejects_a_broken_shader() {
    // The check above can fail: a type error is caught.
    assert!(validate("fn f() -> u32 { return 1.5; }").is_err());
}
