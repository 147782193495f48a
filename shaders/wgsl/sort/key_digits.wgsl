// A sort digit: RADIX (a power of two) digits at SHIFT (a define) of key - key_offset(), shared by the
// 4-bit radix_*.wgsl and the lane-ordered lane_*.wgsl passes, which define RADIX. Define KEY_BASE
// (optional): the sort orders key - key_base[KEY_BASE_WORD] (wrapping) rather than the key, so keys known
// to lie in [base, base + 2^bits) sort in `bits` bits (the keys themselves move unchanged); each pass
// binds key_base itself.

// What the sort subtracts from every key.
fn key_offset() -> u32 {
#if KEY_BASE
    return key_base[KEY_BASE_WORD];
#else
    return 0u;
#endif
}

// The digit of `key` (key - key_offset(), passed in as `base`).
fn key_digit(key: u32, base: u32) -> u32 {
    return ((key - base) >> SHIFT) & (RADIX - 1u);
}
