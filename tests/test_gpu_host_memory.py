"""The read-backs' host memory pool (gma/gpu/host_memory.py): a region is reused only once nothing can
read it any more, views and torch tensors included."""

import gc

import numpy as np
import torch

from gma.gpu.host_memory import PAGE, HostMemoryPool


def _address(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


def test_a_region_comes_back_once_its_array_is_gone():
    pool = HostMemoryPool()
    a = pool.take(3 * PAGE + 5)
    assert a.dtype == np.uint8 and a.shape == (3 * PAGE + 5,) and a.flags.writeable
    first = _address(a)
    a[:] = 7
    del a
    gc.collect()
    b = pool.take(3 * PAGE + 5)
    assert _address(b) == first and pool.reused == 1
    c = pool.take(3 * PAGE + 5)   # b still lives: a new region
    assert _address(c) != first and pool.reused == 1


def test_views_and_tensors_keep_their_region():
    pool = HostMemoryPool()
    raw = pool.take(8 * 1000)
    floats = raw[4000:8000].view(np.float32)
    tensor = torch.from_numpy(floats.reshape(10, 100))
    tensor[:] = 3.0
    start = _address(raw)
    del raw, floats
    gc.collect()
    other = pool.take(8 * 1000)   # the tensor still reads the first region
    assert _address(other) != start
    other[:] = 0
    assert torch.all(tensor == 3.0)
    del tensor
    gc.collect()
    assert _address(pool.take(8 * 1000)) == start


def test_free_regions_beyond_the_limit_are_dropped():
    pool = HostMemoryPool(keep_bytes=2 * PAGE)
    arrays = [pool.take(PAGE) for _ in range(4)]
    del arrays
    gc.collect()
    assert pool.free_bytes == 2 * PAGE
    assert pool.take(0).shape == (0,)
