// Second level of contact reduction for one pair (the body of a merge workgroup), shared by merge.wgsl and
// many_body/merge.wgsl: reads the patches of the pair's `job_count` jobs at job_patches[(job_base + j) *
// MAX_PATCHES..] (counts at job_patch_count[job_base + j]) and writes at most MAX_PATCHES patches to
// patches[out_base..]; returns their number. Called in uniform control flow (the reduction's barriers).

fn merge_jobs(lid: u32, pair: Pair, job_base: u32, job_count: u32, out_base: u32) -> u32 {
    reset_patches(lid);
    var pc = 0u;
    // The jobs' slots form one stream (job by job, 4 slots per patch), cut into batches of BATCH: most
    // jobs hold far fewer than BATCH slots, and a batch costs the same (its barriers and slot rounds)
    // however few candidates it holds.
    var total = 0u;
    for (var j = 0u; j < job_count; j++) {
        total += job_patch_count[job_base + j] * 4u;
    }
    var first_job = 0u; // the job holding stream index `base`, and its first index
    var first_off = 0u;
    // Batches and each invocation's entries loop with the exit test at the end of the pass (lavapipe runs
    // a loop's body once more, masked, after a last pass that ends with the test at the top: here a whole
    // batch; see common.wgsl on loops), inside a test for an empty stream.
    if (total > 0u) {
        var base = 0u;
        loop {
            loop {
                let n = job_patch_count[job_base + first_job] * 4u;
                if (first_off + n > base) {
                    break;
                }
                first_off += n;
                first_job++;
            }
            var cs = cands_empty();
            // This invocation's PER stream entries, one after another: the walk to their jobs goes on from
            // one to the next.
            var j = first_job;
            var off = first_off;
            var q = 0u;
            loop {
                let i = base + lid * PER + q;
                if (i < total) {
                    loop {
                        let n = job_patch_count[job_base + j] * 4u;
                        if (i < off + n) {
                            break;
                        }
                        off += n;
                        j++;
                    }
                    let k = i - off;
                    let p = job_patches[(job_base + j) * MAX_PATCHES + k / 4u];
                    let sl = p.slots[k % 4u];
                    if (sl.w < VALID_BELOW) {
                        let used = select(0u, 1u, p.slots[0].w < VALID_BELOW) + select(0u, 1u, p.slots[1].w < VALID_BELOW)
                            + select(0u, 1u, p.slots[2].w < VALID_BELOW) + select(0u, 1u, p.slots[3].w < VALID_BELOW);
                        let units = p.normal.w / (f32(used) * pair.area_unit);
                        cands_set(&cs, q, sl, vec4<f32>(p.normal.xyz, f32(max(1u, u32(round(units))))));
                    }
                }
                q += 1u;
                if (q >= PER) {
                    break;
                }
            }
            pc = reduce_batch(lid, cs, pc, params.normal_cos, pair.contact_offset, pair.min_separation, true);
            base += BATCH;
            if (base >= total) {
                break;
            }
        }
    }
    workgroupBarrier(); // the last batch's slot writes
    for (var p = lid; p < pc; p += WG) {
        var o: PatchOut;
        o.normal = vec4<f32>(patch_data[pd_normal(p)].xyz, f32(atomicLoad(&patch_ak[ak_area(p)])) * pair.area_unit);
        for (var s = 0u; s < 4u; s++) {
            o.slots[s] = patch_data[pd_slot(p, s)];
        }
        patches[out_base + p] = o;
    }
    return pc;
}
