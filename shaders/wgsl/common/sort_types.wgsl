// Radix sort geometry shared by the three sort passes. 4-bit digits; each thread of a block owns ITEMS
// consecutive keys, which keeps the per-block ranking cheap and the sort stable.
const SORT_WG: u32 = 128u;
const SORT_ITEMS: u32 = 16u;
const SORT_BLOCK: u32 = 2048u;   // SORT_WG * SORT_ITEMS
const RADIX: u32 = 16u;
