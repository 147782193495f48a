// Digits of the lane-ordered radix sort (lane_count.wgsl, lane_scatter.wgsl), for CPU drivers whose
// subgroups have 8 lanes. A workgroup is one subgroup, which a CPU driver runs as one SIMD thread in
// program order; it takes its keys 8 at a time, in order, and counts and ranks them per digit in
// workgroup memory with plain loads and stores: lanes that share a digit learn of each other through
// xor-shuffles, so every lane of a digit stores the same new count and the store order does not matter.
// Defines: SHIFT, DIGIT_BITS (digit width), GROUP_BLOCKS (see LANE_BLOCK), KEY_BASE (optional: the sort
// orders key - key_base[KEY_BASE_WORD], see key_digits.wgsl).
const LANES: u32 = 8u;
const RADIX: u32 = 1u << DIGIT_BITS;
const NO_DIGIT: u32 = RADIX;   // lanes past the end count into this extra bin

// A workgroup takes GROUP_BLOCKS sort blocks (SORT_BLOCK keys each): fewer, larger blocks keep the
// histograms (2^DIGIT_BITS counts per block) and their scan small. The passes are dispatched for
// info.groups_x sort blocks; workgroups past lane_groups() return at once.
const LANE_BLOCK: u32 = SORT_BLOCK * GROUP_BLOCKS;

fn lane_groups(sort_blocks: u32) -> u32 {
    return (sort_blocks + GROUP_BLOCKS - 1u) / GROUP_BLOCKS;
}

// The block of workgroup `w` (of info.groups_x), or one past any block: every GROUP_BLOCKS-th workgroup
// takes one. Lavapipe hands each of its threads a contiguous share of a dispatch's workgroups, so with the
// first lane_groups() workgroups working one thread did the whole pass while the others returned.
fn lane_block(w: u32) -> u32 {
    return select(0xffffffffu, w / GROUP_BLOCKS, w % GROUP_BLOCKS == 0u);
}

#include "sort/key_digits.wgsl"

// The keys [start, end) of workgroup `block` (LANE_BLOCK of them, fewer in the last) among `count` keys.
fn lane_keys(block: u32, count: u32) -> vec2<u32> {
    let start = block * LANE_BLOCK;
    return vec2<u32>(start, min(start + LANE_BLOCK, count));
}

// Of the subgroup's 8 digits `d` (one per lane): how many lanes hold this lane's digit (x) and how many of
// them come before this lane (y). Lane l ^ k lies below l exactly when l has k's highest bit set.
// Constant xor masks: a shuffle whose lane is not a constant is a loop over the lanes on lavapipe.
fn digit_peers(d: u32, lane: u32) -> vec2<u32> {
    var peers = vec2<u32>(1u, 0u);
    peers += peer(subgroupShuffleXor(d, 1u) == d, (lane & 1u) != 0u);
    peers += peer(subgroupShuffleXor(d, 2u) == d, (lane & 2u) != 0u);
    peers += peer(subgroupShuffleXor(d, 3u) == d, (lane & 2u) != 0u);
    peers += peer(subgroupShuffleXor(d, 4u) == d, (lane & 4u) != 0u);
    peers += peer(subgroupShuffleXor(d, 5u) == d, (lane & 4u) != 0u);
    peers += peer(subgroupShuffleXor(d, 6u) == d, (lane & 4u) != 0u);
    peers += peer(subgroupShuffleXor(d, 7u) == d, (lane & 4u) != 0u);
    return peers;
}

fn peer(same: bool, below: bool) -> vec2<u32> {
    return vec2<u32>(u32(same), u32(same && below));
}
