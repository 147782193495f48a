// Digits of the radix sort and a thread's per-digit key counts. Defines: SHIFT (the digit's lowest bit);
// KEY_BASE (optional): the sort orders key - key_base[KEY_BASE_WORD] (wrapping) rather than the key, so
// keys known to lie in [base, base + 2^bits) sort in `bits` bits (the keys themselves move unchanged).
// The passes read the base once per thread (key_offset): lavapipe does not hoist a storage load past
// the stores, so a read per key would be paid per key.
//
// Each of a block's SORT_WG threads (a define, >= RADIX: the count pass clears and writes one digit per
// thread) owns SORT_ITEMS consecutive keys, which keeps the per-block ranking cheap and the sort stable.
// GPUs take 128 threads of 16 keys. CPU drivers take 16 threads of 128 keys (gma/render/gpu_sort.py):
// there a workgroup's threads run one after another anyway, and what a thread does per digit (histogram
// atomics, the per-thread offsets in workgroup memory, the serial per-digit prefix over the threads)
// costs as much as moving its keys when it has only 16 of them.
//
// A thread counts the digits of its SORT_ITEMS keys in registers, one byte per digit (counts reach at
// most SORT_ITEMS <= 128) packed into a vec4<u32> and updated with selects, not a private array indexed
// by the digit, which lavapipe turns into per-lane code. (5-bit digits, one pass fewer for both of the
// renderer's sorts, with counts packed in two vec4s, are slower: the per-thread work per digit, the
// histogram atomics and the per-digit scans, doubles.)
//
// The count and scatter passes take a thread's keys two per loop step, the counts copied into a
// step-local value: lavapipe keeps a variable that a loop carries in memory in a shader with barriers
// (the frame of the coroutine it becomes) and writes it through the loop's lane mask, so the counts go
// through memory once per two keys (four keys per step are no faster).
const RADIX_BITS: u32 = 4u;   // mirrored by gma/render/gpu_sort.py
const RADIX: u32 = 1u << RADIX_BITS;
const SORT_ITEMS: u32 = SORT_BLOCK / SORT_WG;

#include "sort/key_digits.wgsl"

// Counts per digit: digit d in byte d % 4 of component d / 4.
fn add_digit(c: ptr<function, vec4<u32>>, digit: u32) {
    let inc = vec4<u32>(1u << ((digit & 3u) * 8u));
    *c += select(vec4<u32>(0u), inc, vec4<u32>(digit >> 2u) == vec4<u32>(0u, 1u, 2u, 3u));
}

// Component `i & 3` of v, by selects (no dynamic vector indexing).
fn pick4(v: vec4<u32>, i: u32) -> u32 {
    let pair = select(v.xy, v.zw, (i & 2u) != 0u);
    return select(pair.x, pair.y, (i & 1u) != 0u);
}

fn digit_count(c: vec4<u32>, digit: u32) -> u32 {
    return (pick4(c, digit >> 2u) >> ((digit & 3u) * 8u)) & 0xffu;
}
