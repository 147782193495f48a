"""GPU radix sort and prefix sum: exact equality with numpy."""

from __future__ import annotations

import numpy as np
import pytest

from gma.render.gpu_scan import ExclusiveScan
from gma.render.gpu_sort import LANE_GROUP_BLOCKS, SORT_BLOCK, RadixSorter, lane_sort_supported

pytestmark = pytest.mark.gpu

# The 4-bit variant with the CPU drivers' and the GPUs' block geometry, and the lane-ordered variant
# (lavapipe only, where it is the default; gpu_sort.py).
VARIANTS = ["radix16", "radix128", "lanes"]


def sorter(gpu, variant: str) -> RadixSorter:
    if variant == "lanes":
        if not lane_sort_supported(gpu):
            pytest.skip("the lane-ordered sort runs on lavapipe with 8-lane subgroups only")
        return RadixSorter(gpu, lanes=True)
    return RadixSorter(gpu, threads=int(variant[5:]), lanes=False)


LANE_BLOCK = SORT_BLOCK * LANE_GROUP_BLOCKS


@pytest.mark.parametrize("n", [1, 7, 9, 2047, 2049, LANE_BLOCK - 1, LANE_BLOCK + 3, 50_000])
# 32 bits: three lane passes of 11 bits; 22: two of 11; 12: two of 6; 10: one; 4 and 1: one, mostly ties
@pytest.mark.parametrize("bits,high", [(32, 2**32), (22, 2**22), (12, 4000), (10, 1000), (4, 3), (1, 2)])
@pytest.mark.parametrize("variant", VARIANTS)
def test_radix_sort_equals_stable_argsort(gpu, n, bits, high, variant):
    rng = np.random.default_rng(n + bits)
    keys = rng.integers(0, high, n, dtype=np.uint64).astype(np.uint32)  # many duplicates when high small
    sorted_keys, order = sorter(gpu, variant).sort(keys, bits=bits)
    want = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(order, want)
    np.testing.assert_array_equal(sorted_keys, keys[want])


@pytest.mark.parametrize("bits", [32, 22, 10, 4])   # 3, 2, 1, 1 lane passes; 8, 6, 3, 1 radix passes
@pytest.mark.parametrize("variant", VARIANTS)
def test_radix_sort_from_a_separate_source(gpu, bits, variant):
    # encode(source=...): the result lands in the output pair after any number of passes, no copy back.
    keys = np.random.default_rng(bits).integers(0, 2**bits, 20_000, dtype=np.uint64).astype(np.uint32)
    sorted_keys, order = sorter(gpu, variant).sort(keys, bits=bits, separate=True)
    np.testing.assert_array_equal(order, np.argsort(keys, kind="stable"))
    np.testing.assert_array_equal(sorted_keys, keys[order])


@pytest.mark.parametrize("variant", VARIANTS)
def test_radix_sort_orders_only_the_low_bits(gpu, variant):
    # As the tile sort of a replayed render: record numbers ride above the 10 sorted bits, unsorted.
    rng = np.random.default_rng(3)
    keys = (rng.integers(0, 1024, 30_000) | (rng.integers(0, 50, 30_000) << 16)).astype(np.uint32)
    sorted_keys, order = sorter(gpu, variant).sort(keys, bits=10)
    np.testing.assert_array_equal(order, np.argsort(keys & 1023, kind="stable"))
    np.testing.assert_array_equal(sorted_keys, keys[order])


@pytest.mark.parametrize("n", [5, 50_000])
@pytest.mark.parametrize("variant", VARIANTS)
def test_radix_sort_from_a_base_orders_the_keys_above_it(gpu, n, variant):
    # Keys within 2^18 above a base, across a power of two (as the depth keys of a frame): 18 bits of
    # key - base order them as all 32 bits would.
    rng = np.random.default_rng(n)
    base = (1 << 22) - 5000
    keys = (base + rng.integers(0, 1 << 18, n)).astype(np.uint32)
    keys[:2] = [base, base + (1 << 18) - 1]
    sorted_keys, order = sorter(gpu, variant).sort(keys, bits=18, base=base)
    np.testing.assert_array_equal(order, np.argsort(keys, kind="stable"))


def test_lane_sort_is_the_default_where_supported(gpu):
    assert RadixSorter(gpu).lanes == lane_sort_supported(gpu)
    if not lane_sort_supported(gpu):
        with pytest.raises(ValueError, match="lane-ordered"):
            RadixSorter(gpu, lanes=True)


def test_radix_sort_block_geometry(gpu):
    from gma.render.gpu_sort import CPU_SORT_THREADS, GPU_SORT_THREADS

    assert RadixSorter(gpu).threads == (CPU_SORT_THREADS if gpu.is_software else GPU_SORT_THREADS)
    # fewer threads than digits, not a divisor of the block, no keys per thread, an odd number of keys each
    for bad in (8, 24, 4096, 2048):
        with pytest.raises(ValueError, match="sort threads per block"):
            RadixSorter(gpu, threads=bad)


def test_depth_key_bits():
    from gma.render.rasterizer import depth_key_bits

    assert depth_key_bits(np.array([0, 0, 0xFFFFFFFF, 0], np.uint32)) == 1   # nothing listed
    assert depth_key_bits(np.array([0, 7, 100, 100], np.uint32)) == 1
    assert depth_key_bits(np.array([0, 7, (1 << 22) - 1, 1 << 22], np.uint32)) == 1
    assert depth_key_bits(np.array([0, 7, 4178575, 4440715], np.uint32)) == 18


def test_radix_sort_carries_values(gpu):
    keys = np.array([5, 1, 5, 0, 1], np.uint32)
    values = np.array([10, 11, 12, 13, 14], np.uint32)
    k, v = RadixSorter(gpu).sort(keys, values, bits=3)
    np.testing.assert_array_equal(k, [0, 1, 1, 5, 5])
    np.testing.assert_array_equal(v, [13, 11, 14, 10, 12])


@pytest.mark.parametrize("n", [1, 1023, 1024, 1025, 300_000])
def test_exclusive_scan(gpu, n):
    rng = np.random.default_rng(n)
    values = rng.integers(0, 9, n).astype(np.uint32)
    got = ExclusiveScan(gpu).scan(values)
    np.testing.assert_array_equal(got, np.concatenate([[0], np.cumsum(values)[:-1]]).astype(np.uint32))


def test_scan_with_gather(gpu):
    rng = np.random.default_rng(0)
    values = rng.integers(0, 9, 5000).astype(np.uint32)
    index = rng.permutation(5000).astype(np.uint32)
    got = ExclusiveScan(gpu).scan(values, index)
    g = values[index]
    np.testing.assert_array_equal(got, np.concatenate([[0], np.cumsum(g)[:-1]]).astype(np.uint32))
