// Per-contact normals (dispatched when the host reads the contacts: ContactPipeline::read): patches share
// one normal for binning and for friction, but each reduced contact also gets the SDF shape's own outward
// normal at its point, so a contact on a curved surface (a helical flank, a sphere) pushes along its local
// normal. One invocation per contact slot: the contact point (on shape a) is moved back by the query radius
// along the patch normal, taken into shape b's frame, and the normalised SDF gradient there is rotated back
// to the world.
// Only reduced contacts are sampled (at most 4 x max_patches per pair), yet on lavapipe that is 4-5% of the
// nut-bolt pair's contact handling per frame, which the solver, sampling its own, does not need.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> pairs: array<Pair>;
@group(0) @binding(2) var<storage, read> sdf_values: array<u32>;
@group(1) @binding(0) var<storage, read> body_q: array<Transform>;
@group(1) @binding(1) var<storage, read> patches: array<PatchOut>;
@group(1) @binding(2) var<storage, read> patch_counts: array<u32>;
@group(2) @binding(0) var<storage, read_write> contact_normals: array<vec4<f32>>;

@compute @workgroup_size(64)
fn normals(@builtin(global_invocation_id) gid: vec3<u32>) {
    let slot = gid.x;
    let pair_index = gid.y;
    let world = gid.z + params.world_offset;
    if (slot >= MAX_PATCHES * 4u) {
        return;
    }
    let pw = world * params.pair_count + pair_index;
    let out = pw * MAX_PATCHES * 4u + slot;
    let patch_index = slot / 4u;
    if (patch_index >= patch_counts[pw]) {
        contact_normals[out] = vec4<f32>(0.0);
        return;
    }
    let p = patches[pw * MAX_PATCHES + patch_index];
    let c = p.slots[slot % 4u];
    if (c.w >= VALID_BELOW) {
        contact_normals[out] = vec4<f32>(0.0);
        return;
    }
    let pair = pairs[pair_index];
    sdf_bind(pair);
    var body_b = Transform(vec4<f32>(0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0));
    if (pair.body_b != NONE) {
        body_b = body_q[world * params.body_count + pair.body_b];
    }
    let world_b = xf_mul(body_b, Transform(pair.b_pos, pair.b_rot));
    let b_inv = xf_inv(world_b);
    let x = xf_point(b_inv, c.xyz + pair.radius * p.normal.xyz);
    let s = sdf_sample(pair, x);
    let len = length(s.g);
    var n = p.normal.xyz;
    if (len > 0.0) {
        n = quat_rotate(world_b.q, s.g / len);
    }
    contact_normals[out] = vec4<f32>(n, 0.0);
}
