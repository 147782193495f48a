// Radix sort geometry shared by the three sort passes (and the passes that size its dispatches): a
// workgroup sorts a block of SORT_BLOCK keys; how many threads share a block is the sort passes' define
// SORT_WG (sort/radix_digits.wgsl), the same block size either way.
const SORT_BLOCK: u32 = 2048u;
