// The same orthonormal choice as glam's Vec3::any_orthonormal_vector (Duff et al. 2017): the tangent t1 of a
// contact row's normal n (the second tangent is n x t1). Shared by the solver kernels and by kernels that read
// the rows' impulses (solver/mod.rs ANY_ORTHONORMAL_WGSL).
fn any_orthonormal(n: vec3<f32>) -> vec3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return vec3<f32>(b, sign + n.y * n.y * a, -n.y);
}
