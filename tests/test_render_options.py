"""The rasterizer's variants as one frozen value (gma/render/options.py): chosen from the adapter, checked
against it, never changed on a live rasterizer, and keying the pipelines through the shaders' defines."""

from __future__ import annotations

import dataclasses

import pytest

from gma.render import RasterOptions, SurfelRasterizer


def test_the_adapter_chooses_the_options(gpu):
    best = RasterOptions.for_context(gpu)
    assert SurfelRasterizer(gpu).options == best
    assert best.float_atomics == gpu.has_float_atomics and best.project_subgroups == gpu.has_subgroups
    assert best.subgroups == (gpu.is_software and 1 <= gpu.subgroup_size <= 32)
    assert best.tile_walk == (best.subgroups and gpu.subgroup_size == 8)
    assert best.grad_records == (best.tile_walk and gpu.is_lavapipe)
    assert best.work_queues == gpu.is_lavapipe and best.queue_workgroups == gpu.dispatch_threads
    with pytest.raises(dataclasses.FrozenInstanceError):
        best.tile_walk = not best.tile_walk


def test_options_the_adapter_cannot_run_are_refused(gpu, gpu_no_float_atomics):
    best = RasterOptions.for_context(gpu)
    refused = [(gpu, dataclasses.replace(best, queue_workgroups=0), "queue_workgroups 0"),
               (gpu_no_float_atomics, RasterOptions(float_atomics=True), "float atomics"),
               (gpu_no_float_atomics, RasterOptions(subgroups=True), "without subgroups"),
               (gpu, RasterOptions(tile_walk=True), "tile walk needs")]
    if best.tile_walk:
        refused.append((gpu, dataclasses.replace(best, tile_walk=False), "gradient records need"))
    for ctx, options, message in refused:
        with pytest.raises(ValueError, match=message):
            SurfelRasterizer(ctx, options)
    SurfelRasterizer(gpu_no_float_atomics, RasterOptions())   # the plain variants run anywhere


def test_each_options_value_has_its_own_pipelines(gpu):
    best = RasterOptions.for_context(gpu)
    if not best.subgroups:
        pytest.skip("the plain and subgroup rasterizers differ only where subgroups run")
    plain = dataclasses.replace(best, subgroups=False, tile_walk=False, grad_records=False)
    defines = [SurfelRasterizer(gpu, o).raster_defines(3) for o in (best, plain)]
    assert defines[0] != defines[1]
    assert gpu.compute_pipeline("render/rasterize_fwd.wgsl", {**defines[0], "REPLAY": True, "USED_BLOCKS": False}) \
        is not gpu.compute_pipeline("render/rasterize_fwd.wgsl", {**defines[1], "REPLAY": True, "USED_BLOCKS": False})
