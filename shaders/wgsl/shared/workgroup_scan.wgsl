// SPDX-License-Identifier: MIT
// Exclusive prefix sum of one u32 per invocation over a workgroup of SCAN_WG_SIZE invocations,
// in two levels with 4 barriers: invocations 0..SCAN_SEGMENTS each scan one segment of
// SCAN_SEGMENT_LEN values serially, invocation 0 scans the segment totals, and every
// invocation adds its segment's offset. Integer adds only, so the result does not depend on
// scheduling. Must be called from uniform control flow by every invocation of a workgroup of
// exactly SCAN_WG_SIZE invocations.
// Mirrors core/src/cpu/marching_cubes.rs::wg_exclusive_scan (which computes the same sums
// serially).

const SCAN_WG_SIZE: u32 = 256u;
const SCAN_SEGMENTS: u32 = 16u;
const SCAN_SEGMENT_LEN: u32 = 16u;

var<workgroup> sh_scan: array<u32, SCAN_WG_SIZE>;
var<workgroup> sh_scan_segments: array<u32, SCAN_SEGMENTS>;
var<workgroup> sh_scan_total: u32;

struct WgScan {
    // Sum of the values of invocations 0..local_ix.
    exclusive: u32,
    // Sum over the whole workgroup.
    total: u32,
}

fn wg_exclusive_scan(local_ix: u32, value: u32) -> WgScan {
    sh_scan[local_ix] = value;
    workgroupBarrier();
    if local_ix < SCAN_SEGMENTS {
        var running = 0u;
        for (var i = 0u; i < SCAN_SEGMENT_LEN; i++) {
            let ix = local_ix * SCAN_SEGMENT_LEN + i;
            let v = sh_scan[ix];
            sh_scan[ix] = running;
            running += v;
        }
        sh_scan_segments[local_ix] = running;
    }
    workgroupBarrier();
    if local_ix == 0u {
        var running = 0u;
        for (var s = 0u; s < SCAN_SEGMENTS; s++) {
            let v = sh_scan_segments[s];
            sh_scan_segments[s] = running;
            running += v;
        }
        sh_scan_total = running;
    }
    workgroupBarrier();
    var out: WgScan;
    out.exclusive = sh_scan_segments[local_ix / SCAN_SEGMENT_LEN] + sh_scan[local_ix];
    out.total = sh_scan_total;
    // Nobody may overwrite the scratch before everyone has read it.
    workgroupBarrier();
    return out;
}
