// Shared by the prefix-sum passes (render/scan_blocks.wgsl, render/scan_add.wgsl).
const SCAN_BLOCK: u32 = 1024u;   // values per workgroup; mirrors gma/render/gpu_scan.py

struct ScanParams {
    count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};
