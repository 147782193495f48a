// Radix sort geometry shared by the three sort passes (and the passes that size its dispatches): each
// thread of a block owns ITEMS consecutive keys, which keeps the per-block ranking cheap and the sort
// stable. The digit width is the define RADIX_BITS (sort/radix_digits.wgsl).
const SORT_WG: u32 = 128u;
const SORT_ITEMS: u32 = 16u;
const SORT_BLOCK: u32 = 2048u;   // SORT_WG * SORT_ITEMS
