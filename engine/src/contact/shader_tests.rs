//! Every contact shader, at the smallest, default and largest patch budget, parses and validates with naga
//! (no GPU needed).

use super::generate::{shader_source, shader_source_wg, GENERATE_WGSL};
use super::merge::MERGE_WGSL;
use super::normals::NORMALS_WGSL;

/// A validator allowing subgroup operations or not (the portable kernels must not use them).
pub(crate) fn validator(subgroups: bool) -> naga::valid::Validator {
    let caps = if subgroups { naga::valid::Capabilities::SUBGROUP } else { naga::valid::Capabilities::empty() };
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), caps)
}

pub(crate) fn validate(src: &str, subgroups: bool) -> Result<(), String> {
    crate::gpu::validate_wgsl(src, subgroups)
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
            for kinds in super::generate::SdfKinds::combinations() {
                let src = shader_source(wgsl, max_patches, kinds);
                if let Err(e) = validate(&src, false) {
                    panic!("{name}.wgsl with max_patches = {max_patches}, {kinds:?}:\n{e}");
                }
            }
            let src = shader_source_wg(wgsl, max_patches, 64, 4, super::generate::SdfKinds::default(), true);
            if let Err(e) = validate(&src, true) {
                panic!("{name}.wgsl with max_patches = {max_patches}, subgroups:\n{e}");
            }
        }
    }
}

#[test]
fn naga_rejects_a_broken_shader() {
    // The check above can fail: a type error is caught.
    assert!(validate("fn f() -> u32 { return 1.5; }", true).is_err());
    // The portable kernels are checked without subgroup operations: a use of one is caught.
    let sg = "@compute @workgroup_size(64) fn f() { let x = subgroupAdd(1u); }";
    assert!(validate(sg, true).is_ok());
    assert!(validate(sg, false).is_err());
}
