// Shared by the many-body kernels (near.wgsl, contacts.wgsl, solve.wgsl): the parameters and the layout of the
// per-world bookkeeping buffer many_body_meta (u32 words, ManyBodyParams::meta_stride per world; see gpu.rs).

struct ManyBodyParams {
    world_count: u32,
    body_count: u32,
    // Near pairs a world may hold (ManyBodyConfig::max_pairs).
    cap: u32,
    jobs_per_pair: u32,
    // Query triangles per job.
    chunk: u32,
    class_count: u32,
    static_count: u32,
    max_colours: u32,
    meta_stride: u32,
    // Patches a world may hold (ManyBodyConfig::max_patches_per_world).
    patch_budget: u32,
    // Sleeping (ManyBodyConfig::sleep; solve.wgsl): frames still before a body sleeps (0: never), the
    // largest displacement [m] and cos(largest rotation / 2) from the reference pose.
    sleep_frames: u32,
    sleep_distance: f32,
    sleep_half_cos: f32,
    // vec4 index of the sleeping state in the solver scratch (solve.wgsl rest_index).
    rest_base: u32,
    _pad1: u32,
    _pad2: u32,
}

// Per-dispatch parameters (a dynamic-offset uniform): the colouring round, or the solver pass's colour
// and phase.
// (The phase's warm and resample flags pick the many_body_pass entry point on the host, gpu.rs PHASES.)
struct PassParams {
    index: u32,
    bias: u32,
    _pad0: u32,
    _pad1: u32,
}

// Head words of a world's meta block.
const M_COUNT: u32 = 0u;        // near pairs in the list
const M_FLAGS: u32 = 1u;        // FLAG_* bits (mod.rs); non-zero: the world is not stepped this frame
const M_OLD_COUNT: u32 = 2u;    // near pairs last frame
const M_COLOURS: u32 = 3u;      // colours in use
const M_PATCHES: u32 = 4u;      // patches in use
const M_COLOUR_OFF: u32 = 16u;  // 33 words: start of colour c's list, c = 0..32
const M_HEAD: u32 = 64u;

const FLAG_PAIRS: u32 = 1u;
const FLAG_COLOURS: u32 = 2u;
const FLAG_ROUNDS: u32 = 4u;
const FLAG_PATCHES: u32 = 8u;
const FLAG_RECOUNT: u32 = 16u;
const UNCOLOURED: u32 = 0xffffffffu;
const COLOUR_NONE: u32 = 255u;

fn meta_base(w: u32) -> u32 {
    return w * cp.meta_stride;
}
// Per body (n words each): near pairs (i, j > i) and statics; pairs (j < i, i); their list offsets.
fn m_count_a(w: u32) -> u32 { return meta_base(w) + M_HEAD; }
fn m_count_b(w: u32) -> u32 { return m_count_a(w) + cp.body_count; }
fn m_off_a(w: u32) -> u32 { return m_count_a(w) + 2u * cp.body_count; }
fn m_off_b(w: u32) -> u32 { return m_count_a(w) + 3u * cp.body_count; }
// Per near pair (cap words each).
fn m_pairs(w: u32) -> u32 { return m_count_a(w) + 4u * cp.body_count; }
fn m_blist(w: u32) -> u32 { return m_pairs(w); }                  // pairs with body b, by body b
fn m_colour(w: u32) -> u32 { return m_pairs(w) + cp.cap; }        // (round << 8) | colour, or UNCOLOURED
fn m_colour_list(w: u32) -> u32 { return m_pairs(w) + 2u * cp.cap; } // pairs by colour
fn m_old_a(w: u32) -> u32 { return m_pairs(w) + 3u * cp.cap; }    // last frame's keys (sorted)
fn m_old_b(w: u32) -> u32 { return m_pairs(w) + 4u * cp.cap; }
fn m_patch_count(w: u32) -> u32 { return m_pairs(w) + 5u * cp.cap; }
fn m_candidates(w: u32) -> u32 { return m_pairs(w) + 6u * cp.cap; }
fn m_row_first(w: u32) -> u32 { return m_pairs(w) + 7u * cp.cap; }   // first patch of the pair's rows
fn m_old_row_first(w: u32) -> u32 { return m_pairs(w) + 8u * cp.cap; }

// Indirect dispatch arguments (x, y, z) in many_body_args.
const A_PAIRS: u32 = 0u;     // one invocation per near pair (64 per workgroup)
const A_GENERATE: u32 = 3u;  // one workgroup per (near pair, job, world)
const A_MERGE: u32 = 6u;     // one workgroup per near pair
const A_COLOUR: u32 = 9u;    // colour c at A_COLOUR + 3c: one invocation per pair of that colour
