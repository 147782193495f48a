// Radix sort, pass 3 of 3: stable scatter of keys and values to their digit's place. Within a block,
// a key's rank is (keys of the same digit owned by earlier threads) + (earlier keys of the same thread).
// (Packing the tile and surfel ids into one key would not pay: without reading the values a sort on
// lavapipe is no faster; the ranking, not the memory traffic, bounds this pass.)
#include "common/render_types.wgsl"
#include "common/sort_types.wgsl"
#include "sort/radix_digits.wgsl"

@group(0) @binding(0) var<storage, read> info: DispatchInfo;
@group(0) @binding(1) var<storage, read> hist: array<u32>;       // scanned: output offsets
@group(0) @binding(2) var<storage, read> keys_in: array<u32>;
@group(0) @binding(3) var<storage, read> vals_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> vals_out: array<u32>;
#if KEY_BASE
@group(0) @binding(6) var<storage, read> key_base: array<u32>;   // see key_offset
#endif

var<workgroup> offsets: array<u32, RADIX * SORT_WG>;   // [RADIX][SORT_WG]: per digit, per thread

// This thread's first output positions for digits 4w .. 4w + 3 (read into registers once, so that each
// key picks its digit's by selects).
fn bases_of(lid: u32, w: u32) -> vec4<u32> {
    let d = 4u * w;
    return vec4<u32>(offsets[d * SORT_WG + lid], offsets[(d + 1u) * SORT_WG + lid],
                     offsets[(d + 2u) * SORT_WG + lid], offsets[(d + 3u) * SORT_WG + lid]);
}

@compute @workgroup_size(SORT_WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let count = info.count;
    let block = wg.x;
    let start = block * SORT_BLOCK + lid * SORT_ITEMS;
    let base = key_offset();
    var counts = vec4<u32>(0u);   // per digit (radix_digits.wgsl)
    for (var i = 0u; i < SORT_ITEMS; i += 2u) {
        var c = counts;
        count_key(&c, start + i, count, base);
        count_key(&c, start + i + 1u, count, base);
        counts = c;
    }
    for (var d = 0u; d < RADIX; d++) {
        offsets[d * SORT_WG + lid] = digit_count(counts, d);
    }
    workgroupBarrier();
    if lid < RADIX {
        // Thread `lid` turns digit lid's per-thread counts into global output positions.
        var run = hist[lid * info.groups_x + block];
        for (var t = 0u; t < SORT_WG; t++) {
            let c = offsets[lid * SORT_WG + t];
            offsets[lid * SORT_WG + t] = run;
            run += c;
        }
    }
    workgroupBarrier();
    let b0 = bases_of(lid, 0u);
    let b1 = bases_of(lid, 1u);
    let b2 = bases_of(lid, 2u);
    let b3 = bases_of(lid, 3u);
    var seen = vec4<u32>(0u);   // this thread's earlier keys, per digit
    for (var i = 0u; i < SORT_ITEMS; i += 2u) {
        var sn = seen;
        scatter_key(&sn, start + i, count, base, b0, b1, b2, b3);
        scatter_key(&sn, start + i + 1u, count, base, b0, b1, b2, b3);
        seen = sn;
    }
}

fn count_key(c: ptr<function, vec4<u32>>, idx: u32, count: u32, base: u32) {
    if idx < count {
        add_digit(c, key_digit(keys_in[idx], base));
    }
}

fn scatter_key(seen: ptr<function, vec4<u32>>, idx: u32, count: u32, base: u32, b0: vec4<u32>, b1: vec4<u32>,
               b2: vec4<u32>, b3: vec4<u32>) {
    if idx < count {
        let key = keys_in[idx];
        let digit = key_digit(key, base);
        let w = digit >> 2u;
        let bases = select(select(b0, b1, (w & 1u) != 0u), select(b2, b3, (w & 1u) != 0u), (w & 2u) != 0u);
        let pos = pick4(bases, digit) + digit_count(*seen, digit);
        add_digit(seen, digit);
        keys_out[pos] = key;
        vals_out[pos] = vals_in[idx];
    }
}
