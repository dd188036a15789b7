//! The Gauss-Seidel sweeps of a CPU step: one pass over a world's rows in (pair, patch, slot) order, each
//! patch solved `patch_iters` times per sweep (`link_patch_iters` where it touches an articulation link),
//! row by row ([`solve_row`], the twin of solver.wgsl's `solve_row`) or, for an articulated patch's
//! passes after its first, on the patch's own Delassus matrix ([`solve_patch_block`]).

use super::rows::{dir_rel, Row, RowCache, RowDirection, StepVelocities, SubstepInputs};
use crate::contact::generate::{sdf_sample_cpu, RigidTransform};
use glam::{Quat, Vec3, Vec4};

/// One sweep over the rows, in (pair, patch, slot) order: each patch's rows are solved once with
/// `resample`, then `patch_iters - 1` more times on the sampled geometry (solver.wgsl's `sweep`).
///
/// In an articulated substep a patch's passes after its first (which samples the rows and builds their
/// caches) run as one block ([`solve_patch_block`]) when every row has its [`RowDirection`]s: the same
/// Gauss-Seidel updates in the same order, on the patch's own Delassus matrix. `blocks` holds those
/// matrices, one per patch in row order, built at the patch's first block after a resampling sweep (the
/// caches they come from stand until then); None: every pass row by row
/// ([`PatchSweep::Rows`](super::PatchSweep::Rows)).
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_rows(
    ctx: &SubstepInputs,
    rows: &mut [Row],
    idle: &mut [RowIdleTest],
    pos: &[(Vec3, Quat)],
    vel: &mut StepVelocities,
    bias: bool,
    resample: bool,
    mut blocks: Option<&mut Vec<Option<PatchBlock>>>,
) {
    if let (true, Some(b)) = (resample, blocks.as_mut()) {
        b.clear();
    }
    let mut first = 0;
    for (k, patch) in rows.chunk_by_mut(|x, y| (x.pair, x.patch) == (y.pair, y.patch)).enumerate() {
        let idle = &mut idle[first..first + patch.len()];
        first += patch.len();
        let link = ctx.slot[patch[0].a].is_some() || ctx.slot[patch[0].b].is_some();
        let passes = if link { ctx.cfg.patch_iters.max(ctx.cfg.link_patch_iters) } else { ctx.cfg.patch_iters };
        let mut pass = 0;
        if resample {
            for i in 0..patch.len() {
                solve_row(ctx, patch, i, pos, vel, bias, true);
                idle[i] = RowIdleTest::of(ctx, &patch[i]);
            }
            pass = 1;
        }
        if let (true, Some(blocks)) = (passes - pass.min(passes) >= 2, blocks.as_mut()) {
            if blocks.len() <= k {
                blocks.resize(k + 1, None);
            }
            if blocks[k].is_none() {
                blocks[k] = PatchBlock::new(patch);
            }
            if let Some(block) = &blocks[k] {
                solve_patch_block(ctx, patch, block, vel, bias, passes - pass);
                continue;
            }
        }
        for _ in pass..passes {
            for i in 0..patch.len() {
                if idle[i].stays(&patch[i], vel, bias) {
                    continue;
                }
                solve_row(ctx, patch, i, pos, vel, bias, false);
            }
        }
    }
}

/// What tells a row whether an update leaves it as it is, kept apart from the rows (which are large) so
/// that a sweep reads it in one cache line: most rows within the contact offset hold no impulse and take
/// none (the Franka's nut on the thread: ~13 of ~200 rows push), and for them the update is only this
/// normal test. Its quantities are copies of the row's normal [`RowDirection`] and the speculative targets, so
/// the test is [`solve_row`]'s own, bitwise. `mass` 0: no test (no RowDirection, or not yet cached).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RowIdleTest {
    d: Vec3,
    jac: [Vec3; 2],
    mass: f32,
    /// The normal's target velocity in position sweeps (with bias) and velocity sweeps [m/s].
    target: [f32; 2],
    a: u32,
    b: u32,
}

impl RowIdleTest {
    /// The test of row `r` as cached now.
    fn of(ctx: &SubstepInputs, r: &Row) -> Self {
        // With friction pooled over the patch a row without normal impulse may still take friction.
        if ctx.cfg.friction_per_patch {
            return RowIdleTest::default();
        }
        let (Some(_), Some(c)) = (r.normal, r.cache.as_ref()) else { return RowIdleTest::default() };
        let Some(dirs) = c.link.as_ref() else { return RowIdleTest::default() };
        if c.k[0] <= 0.0 {
            return RowIdleTest::default();
        }
        let n = &dirs[0];
        RowIdleTest {
            d: n.d,
            jac: n.jac,
            mass: n.mass,
            target: [normal_target(ctx, r.sep, true), normal_target(ctx, r.sep, false)],
            a: r.a as u32,
            b: r.b as u32,
        }
    }

    /// Whether [`solve_row`] would leave row `r` unchanged and apply nothing: it holds no impulse, and the
    /// normal update clamps to zero (then friction, limited by the row's own normal impulse, has nothing to
    /// give).
    #[inline]
    fn stays(&self, r: &Row, vel: &StepVelocities, bias: bool) -> bool {
        if self.mass == 0.0 || r.lambda_n != 0.0 || r.lambda_t != [0.0; 2] {
            return false;
        }
        let rel = dir_rel(self.d, &self.jac, vel, self.a as usize, self.b as usize);
        let dn = (self.target[!bias as usize] - rel) * self.mass;
        // (0 + dn).max(0) is 0 unless dn > 0 (f32::max takes 0 over NaN).
        !(dn > 0.0)
    }
}

/// The normal's target relative velocity [m/s] at separation `s` [m]: speculative when separated, bounded
/// depenetration when penetrating (position sweeps, `bias`), none otherwise.
#[inline]
fn normal_target(ctx: &SubstepInputs, s: f32, bias: bool) -> f32 {
    if s > 0.0 {
        -s / ctx.h
    } else if bias {
        (-s / ctx.h).min(ctx.cfg.max_depenetration_velocity)
    } else {
        0.0
    }
}

/// The most rows a patch holds (its contact slots), and their directions (normal, two tangents each).
const PATCH_ROWS: usize = 4;
const PATCH_DIRS: usize = 3 * PATCH_ROWS;

/// A patch's Delassus matrix over its rows' directions (row j's normal, tangent 1, tangent 2 at 3j, 3j + 1,
/// 3j + 2): `w[d][e]` is the change of direction d's relative velocity [m/s] per N s along direction e,
/// from the [`RowDirection`]s (what `e.apply` moves, read as `d.rel` reads it). Rows without a normal this
/// substep have zero rows and columns.
#[derive(Clone, Debug)]
pub(super) struct PatchBlock {
    w: [[f32; PATCH_DIRS]; PATCH_DIRS],
}

impl PatchBlock {
    /// The block of `patch`, or None where a row that takes part has no [`RowDirection`]s (no articulation
    /// response, or more link bodies than one holds) or the patch has more rows than slots.
    fn new(patch: &[Row]) -> Option<Self> {
        if patch.len() > PATCH_ROWS {
            return None;
        }
        let mut dirs: [Option<&[RowDirection; 3]>; PATCH_ROWS] = [None; PATCH_ROWS];
        for (j, r) in patch.iter().enumerate() {
            if r.normal.is_some() {
                dirs[j] = Some(r.cache.as_ref()?.link.as_ref()?);
            }
        }
        let mut w = [[0.0f32; PATCH_DIRS]; PATCH_DIRS];
        for (i, ri) in patch.iter().enumerate() {
            let Some(di) = dirs[i] else { continue };
            for (j, dj) in dirs.iter().enumerate().take(patch.len()) {
                let Some(dj) = dj else { continue };
                for (a, da) in di.iter().enumerate() {
                    for (b, db) in dj.iter().enumerate() {
                        let mut x = 0.0;
                        for (body, dv) in &db.moved[..db.moved_len as usize] {
                            let body = *body as usize;
                            if body == ri.a {
                                x += dv[0].dot(da.d) + dv[1].dot(da.jac[0]);
                            }
                            if body == ri.b {
                                x -= dv[0].dot(da.d) + dv[1].dot(da.jac[1]);
                            }
                        }
                        w[3 * i + a][3 * j + b] = x;
                    }
                }
            }
        }
        Some(PatchBlock { w })
    }
}

/// `passes` Gauss-Seidel passes over a patch's rows on their sampled geometry, as many [`solve_row`] passes
/// without resampling: the same updates in the same order, each direction's relative velocity kept up to
/// date through the patch's Delassus matrix instead of read from the bodies, and the passes' summed
/// impulse changes applied to the bodies once at the end (the velocities of bodies outside the patch are
/// not read meanwhile). Equal to the row passes up to rounding. Why: a finger pad's rows are swept
/// `link_patch_iters` (8) times per sweep, and each row pass reads two bodies and moves every link body
/// (a [`RowDirection`] apply); on the 12 x 12 matrix a direction's update is 12 products.
fn solve_patch_block(
    ctx: &SubstepInputs,
    patch: &mut [Row],
    block: &PatchBlock,
    vel: &mut StepVelocities,
    bias: bool,
    passes: u32,
) {
    let cfg = ctx.cfg;
    let len = patch.len();
    let n_dirs = 3 * len;
    let mut rel = [0.0f32; PATCH_DIRS];
    let mut moved = [0.0f32; PATCH_DIRS];
    for (j, r) in patch.iter().enumerate() {
        if let (Some(_), Some(dirs)) = (r.normal, r.cache.as_ref().and_then(|c| c.link.as_ref())) {
            for (e, d) in dirs.iter().enumerate() {
                rel[3 * j + e] = d.rel(vel, r.a, r.b);
            }
        }
    }
    // A change x along direction e: every direction's relative velocity follows.
    let push = |rel: &mut [f32; PATCH_DIRS], moved: &mut [f32; PATCH_DIRS], e: usize, x: f32| {
        moved[e] += x;
        for (r, w) in rel[..n_dirs].iter_mut().zip(&block.w) {
            *r += w[e] * x;
        }
    };
    for _ in 0..passes {
        for i in 0..len {
            let r = &patch[i];
            if r.normal.is_none() {
                continue;
            }
            let Some(c) = r.cache.as_ref() else { continue };
            let Some(dirs) = c.link.as_ref() else { continue };
            if c.k[0] <= 0.0 {
                continue;
            }
            let target = normal_target(ctx, r.sep, bias);
            let (mu, k, masses) = (r.mu, c.k, [dirs[0].mass, dirs[1].mass, dirs[2].mass]);
            let dn = (target - rel[3 * i]) * masses[0];
            let new = (r.lambda_n + dn).max(0.0);
            let d = new - r.lambda_n;
            patch[i].lambda_n = new;
            // Zero updates skipped, as in solve_row.
            if d != 0.0 {
                push(&mut rel, &mut moved, 3 * i, d);
            }
            if mu > 0.0 {
                let limit = if cfg.friction_per_patch {
                    mu * patch.iter().map(|o| o.lambda_n).sum::<f32>() / len.max(1) as f32
                } else {
                    mu * new
                };
                if limit == 0.0 && patch[i].lambda_t == [0.0; 2] {
                    continue;
                }
                for j in 0..2 {
                    if k[1 + j] <= 0.0 {
                        continue;
                    }
                    let dt = -rel[3 * i + 1 + j] * masses[1 + j];
                    let old = patch[i].lambda_t[j];
                    let new = (old + dt).clamp(-limit, limit);
                    patch[i].lambda_t[j] = new;
                    if new != old {
                        push(&mut rel, &mut moved, 3 * i + 1 + j, new - old);
                    }
                }
            }
        }
    }
    for (j, r) in patch.iter().enumerate() {
        if let Some(dirs) = r.cache.as_ref().and_then(|c| c.link.as_ref()) {
            for (e, d) in dirs.iter().enumerate() {
                if moved[3 * j + e] != 0.0 {
                    d.apply(vel, moved[3 * j + e]);
                }
            }
        }
    }
}

/// One Gauss-Seidel update of row `i` of a patch's rows (solver.wgsl's `solve_row`).
fn solve_row(
    ctx: &SubstepInputs,
    patch: &mut [Row],
    i: usize,
    pos: &[(Vec3, Quat)],
    vel: &mut StepVelocities,
    bias: bool,
    resample: bool,
) {
    if (resample || patch[i].cache.is_none()) && !prepare_row(ctx, &mut patch[i], pos, resample) {
        return;
    }
    let cfg = ctx.cfg;
    let pooled = cfg.friction_per_patch;
    let len = patch.len();
    // The row and its patch's other rows, so the cache is read in place while the row's impulses change.
    let (before, rest) = patch.split_at_mut(i);
    let (r, after) = rest.split_first_mut().expect("row index within its patch");
    let (Some(n), Some(c)) = (r.normal, r.cache.as_ref()) else { return };
    let s = r.sep;
    let (a, b) = (r.a, r.b);
    // The lever form's relative velocity (rows without LinkDirs), reading the cache in place.
    let rel = |vel: &StepVelocities| {
        let l = &c.lever;
        (vel.v[a][0] + vel.v[a][1].cross(l.ra)) - (vel.v[b][0] + vel.v[b][1].cross(l.rb))
    };
    let k = c.k[0];
    if k <= 0.0 {
        return;
    }
    let target = normal_target(ctx, s, bias);
    let dn = match &c.link {
        Some(dirs) => (target - dirs[0].rel(vel, a, b)) * dirs[0].mass,
        None => (target - rel(vel).dot(n)) / k,
    };
    let new = (r.lambda_n + dn).max(0.0);
    let d = new - r.lambda_n;
    r.lambda_n = new;
    // Most rows within the contact offset stay separated and take no impulse (the Franka's nut on the
    // thread: 13 of ~200 rows pushing): an update of zero moves nothing, so it is skipped, here and below.
    if d != 0.0 {
        match &c.link {
            Some(dirs) => dirs[0].apply(vel, d),
            None => ctx.apply(r, &c.lever, vel, n * d),
        }
    }
    let mu = r.mu;
    if mu > 0.0 {
        let limit = if pooled {
            // The patch's normal impulse per contact (solver.wgsl's patch_normal_share), summed in slot order.
            let sum = before.iter().map(|o| o.lambda_n).chain([r.lambda_n]).chain(after.iter().map(|o| o.lambda_n));
            mu * sum.sum::<f32>() / len.max(1) as f32
        } else {
            mu * r.lambda_n
        };
        // No friction to give and none held: the clamp would leave both tangents at zero.
        if limit == 0.0 && r.lambda_t == [0.0; 2] {
            return;
        }
        for j in 0..2 {
            let kt = c.k[1 + j];
            if kt <= 0.0 {
                continue;
            }
            let dt = match &c.link {
                Some(dirs) => -dirs[1 + j].rel(vel, a, b) * dirs[1 + j].mass,
                None => -rel(vel).dot(c.tangents[j]) / kt,
            };
            let new = (r.lambda_t[j] + dt).clamp(-limit, limit);
            let d = new - r.lambda_t[j];
            r.lambda_t[j] = new;
            if d != 0.0 {
                match &c.link {
                    Some(dirs) => dirs[1 + j].apply(vel, d),
                    None => ctx.apply(r, &c.lever, vel, c.tangents[j] * d),
                }
            }
        }
    }
}

/// A row's sample (with `resample`: its normal and separation at the current poses) and its cache
/// ([`RowCache`]), built where missing. Out of line: a sweep reuses both, and with this inlined the
/// sweep's update copies the cache through the stack (about a third of the solve in store-forwarding
/// stalls under perf). False where the row has no normal (the SDF had no gradient there).
#[inline(never)]
fn prepare_row(ctx: &SubstepInputs, r: &mut Row, pos: &[(Vec3, Quat)], resample: bool) -> bool {
    let cfg = ctx.cfg;
    let n = if resample {
        let ((pa, qa), (pb, qb)) = (pos[r.a], pos[r.b]);
        let pair = &ctx.flat.pairs[r.pair];
        let x = pa + qa * r.anchor_a;
        // The SDF shape's frame: body b's pose times the shape's pose on it.
        let body_b = RigidTransform { p: pb, q: Vec4::from(qb) };
        let shape_b = body_b.mul(&RigidTransform {
            p: Vec3::new(pair.b_pos[0], pair.b_pos[1], pair.b_pos[2]),
            q: Vec4::from_array(pair.b_rot),
        });
        let (phi, g) = sdf_sample_cpu(pair, &ctx.flat.sdf_values, shape_b.inv().point(x));
        let glen = g.length();
        if glen <= 0.0 {
            r.normal = None;
            return false;
        }
        let n = shape_b.rotate(g / glen);
        r.normal = Some(n);
        r.sep = phi - pair.radius - cfg.rest_offset;
        r.cache = None;
        n
    } else {
        match r.normal {
            Some(n) => n,
            None => return false,
        }
    };
    if r.cache.is_none() {
        let lever = ctx.lever(r, pos, n);
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let k = [ctx.eff(r, &lever, n), ctx.eff(r, &lever, t1), ctx.eff(r, &lever, t2)];
        let mut link = ctx
            .link_dir(r, &lever, n)
            .and_then(|dn| Some([dn, ctx.link_dir(r, &lever, t1)?, ctx.link_dir(r, &lever, t2)?]));
        for (dir, k) in link.iter_mut().flatten().zip(k) {
            dir.mass = if k > 0.0 { 1.0 / k } else { 0.0 };
        }
        r.cache = Some(RowCache { lever, tangents: [t1, t2], k, link });
    }
    true
}
