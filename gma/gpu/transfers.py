"""Counting bytes and time spent crossing between host memory and GPU buffers."""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass


@dataclass
class TransferStats:
    """Running totals of host→GPU uploads and GPU→host downloads (bytes, seconds, calls).

    Upload time is the time to hand data to the queue (the copy into the driver's staging memory).
    Download time includes waiting for the compute queued before the read, unless ``wait_for_compute``
    is set: then ``GpuContext.read_many`` first waits for that work outside the timing, so that its
    download time is the copy and map alone. That wait is one more round trip to the device (a fence
    read), so only benchmarks that report transfer times set it; ``GpuContext.read`` always includes the
    wait."""

    bytes_up: int = 0
    bytes_down: int = 0
    seconds_up: float = 0.0
    seconds_down: float = 0.0
    calls_up: int = 0
    calls_down: int = 0
    wait_for_compute: bool = False

    @contextmanager
    def upload(self, nbytes: int):
        t0 = time.perf_counter()
        yield
        self.seconds_up += time.perf_counter() - t0
        self.bytes_up += int(nbytes)
        self.calls_up += 1

    @contextmanager
    def download(self, nbytes: int):
        t0 = time.perf_counter()
        yield
        self.seconds_down += time.perf_counter() - t0
        self.bytes_down += int(nbytes)
        self.calls_down += 1

    def reset(self) -> None:
        self.__init__(wait_for_compute=self.wait_for_compute)

    def summary(self) -> str:
        return (
            f"up {self.bytes_up / 1e6:.2f} MB in {self.calls_up} calls ({self.seconds_up * 1e3:.2f} ms), "
            f"down {self.bytes_down / 1e6:.2f} MB in {self.calls_down} calls ({self.seconds_down * 1e3:.2f} ms)"
        )
