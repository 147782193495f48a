"""Drawing, separated from any window: the same :class:`FrameRenderer` draws into a window's surface
texture, into an offscreen texture for ``gma render`` and for tests.

A frame is three submissions and no readback:
1. the source's posing (``GpuPoser`` skinning + surfel placement into the renderer's input buffers),
   and on cheaper frames the thinning of the surfels (:class:`gma.render.subset.SurfelSubset`);
2. the surfel renderer into an rgba8unorm storage image (``SurfelRasterizer.render_to_texture``), at
   the window's size or, on cheaper frames, smaller (:class:`gma.view.quality.FrameQuality`);
3. one render pass into the target: blit of that image (stretched when smaller), then the mesh overlays
   (depth pre-pass, coarse surfels, wireframe, normals, selection highlight) and screen-space lines.
A frame whose view has not changed since the last full frame skips step 2 and shows that image again.
``SurfelRasterizer.grow_capacity`` (a 4-byte read) runs only every ``capacity_every`` frames, except that a
full frame is never left with dropped surfels: the first full frame of a source is checked at once and
redrawn if it overflowed the intersection capacity, and a later full frame is checked before it is shown
again (its work is finished by then, so the read does not stall).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import wgpu

from gma.core.camera import Camera
from gma.gpu import GpuContext
from gma.render.rasterizer import SurfelRasterizer
from gma.render.subset import SurfelSubset, spread_order
from gma.view.pipelines import DEPTH_FORMAT, ViewerPipelines, clip_matrix
from gma.view.quality import FULL, FrameQuality
from gma.view.source import SurfelSource

__all__ = ["DrawOptions", "FrameRenderer", "Scene", "ScreenImage"]

UNIFORM = wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST
OFFSCREEN_FORMAT = wgpu.TextureFormat.rgba8unorm


@dataclass
class DrawOptions:
    """What a frame shows. Colours are RGB(A) in [0, 1]."""

    background: tuple[float, float, float] = (1.0, 1.0, 1.0)
    surfels: bool = True            # the surfel image (off: background only, e.g. to inspect the mesh)
    wireframe: bool = False         # posed mesh edges, hidden lines removed
    normals: bool = False           # one line per face along its normal
    coarse: bool = False            # one disc per face, coloured by normal (the coarse surfel layer)
    selection: bool = True          # highlight of the selected faces
    wire_color: tuple = (0.1, 0.1, 0.1, 0.6)
    normal_color: tuple = (0.1, 0.3, 1.0, 1.0)
    highlight_color: tuple = (1.0, 0.45, 0.0, 0.55)
    normal_length: float = 0.02     # metres
    coarse_radius: float = 0.7      # disc radius as a fraction of sqrt(face area)


@dataclass
class Scene:
    """A source plus what is drawn over it. ``selection`` holds selected face ids [K] (int); assign a new
    array through :meth:`set_selection` so the renderer knows to re-upload it."""

    source: SurfelSource
    options: DrawOptions = field(default_factory=DrawOptions)
    selection: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    selection_version: int = 0

    def set_selection(self, face_ids) -> None:
        self.selection = np.asarray(face_ids, np.int64).reshape(-1)
        self.selection_version += 1


@dataclass
class ScreenImage:
    """An RGBA image drawn over the frame as a quad (stamp preview, donor thumbnail). ``image`` [h, w, 4]
    uint8 or float in [0, 1]; ``corners`` [4, 2] pixels of its top-left, top-right, bottom-right and
    bottom-left corners; ``key`` names the image's content: the texture is uploaded once per key, so a
    quad that only moves costs one 64-byte write per frame."""

    image: np.ndarray
    corners: np.ndarray
    key: object
    opacity: float = 1.0


def _edges(faces: np.ndarray) -> np.ndarray:
    """Unique undirected edges [E, 2] of a triangle mesh [F, 3]."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


class FrameRenderer:
    """Owns the intermediate image, depth buffer, pipelines and per-mesh overlay buffers of one device."""

    def __init__(self, ctx: GpuContext, capacity_every: int = 30):
        self.ctx = ctx
        self.rasterizer = SurfelRasterizer(ctx)
        self.subset = SurfelSubset(ctx)
        self.pipelines = ViewerPipelines(ctx)
        self.capacity_every = capacity_every
        self.frames = 0
        self._image = self._depth = None
        self._image_size = self._depth_size = (0, 0)
        self._background = ctx.buffer(16, "viewer.background")
        self._background_value: tuple | None = None
        self._overlay_params = {k: ctx.buffer(96, f"viewer.overlay.{k}", UNIFORM)
                                for k in ("depth", "wire", "highlight", "normals", "coarse")}
        self._lines_params = ctx.buffer(32, "viewer.lines", UNIFORM)
        self._mesh_key = None
        self._edges_buf = None
        self._num_edges = 0
        self._sel_buf = None
        self._sel_key = None
        self._num_sel = 0
        self._offscreen = None
        self._images: dict = {}  # slot -> (key, texture, bind group, params buffer, vertex buffer)
        self._sampler = None
        self.last_state = None
        self._drawn: tuple | None = None  # (view key, quality) of the surfel image in self._image
        self.surfel_frames = 0  # frames that ran the surfel renderer (the others reused its image)
        self._spread: tuple | None = None  # (source id, count, order) for the cheaper frames' surfels
        self._drawn_capacity = 0  # intersection capacity the image in self._image was drawn with
        self._drawn_checked = True  # whether that image is known to hold every intersection
        self._checked_sources: set = set()  # sources whose first full frame was checked

    # -- resources ------------------------------------------------------------------------------------
    def _ensure_image(self, w: int, h: int) -> None:
        if self._image_size != (w, h):
            self.ctx.check_image_size(w, h, "the frame")
            self._image = self.ctx.device.create_texture(
                size=(w, h, 1), format=wgpu.TextureFormat.rgba8unorm,
                usage=wgpu.TextureUsage.STORAGE_BINDING | wgpu.TextureUsage.TEXTURE_BINDING, label="viewer.image")
            self._image_view = self._image.create_view()
            self._blit_bind = self.ctx.device.create_bind_group(
                layout=self.pipelines.blit_layout, entries=[{"binding": 0, "resource": self._image_view}])
            self._blit_scaled_bind = self.ctx.device.create_bind_group(
                layout=self.pipelines.blit_scaled_layout,
                entries=[{"binding": 0, "resource": self._image_view}, {"binding": 1, "resource": self._linear()}])
            self._image_size = (w, h)
            self._drawn = None

    def _linear(self):
        if self._sampler is None:
            self._sampler = self.ctx.device.create_sampler(mag_filter="linear", min_filter="linear")
        return self._sampler

    def _ensure_depth(self, w: int, h: int) -> None:
        if self._depth_size != (w, h):
            self._depth = self.ctx.device.create_texture(size=(w, h, 1), format=DEPTH_FORMAT,
                                                         usage=wgpu.TextureUsage.RENDER_ATTACHMENT)
            self._depth_view = self._depth.create_view()
            self._depth_size = (w, h)

    def _ensure_mesh(self, scene: Scene) -> None:
        mesh = scene.source.mesh
        key = (id(mesh.positions), id(mesh.faces))
        if key != self._mesh_key:
            faces = scene.source.body.faces.numpy()
            edges = _edges(faces)
            self._edges_buf = self.ctx.upload(edges.astype(np.uint32), "viewer.edges")
            self._num_edges = len(edges)
            self._mesh_key, self._sel_key = key, None
            self._mesh_binds = {}
        if (key, scene.selection_version) != self._sel_key:
            ids = scene.selection.astype(np.uint32)
            self._num_sel = len(ids)
            self._sel_buf = self.ctx.upload(ids if len(ids) else np.zeros(1, np.uint32), "viewer.selection")
            self._sel_key = (key, scene.selection_version)
            self._mesh_binds.pop("highlight", None)

    def _mesh_bind(self, kind: str, mesh, items):
        bind = self._mesh_binds.get(kind)
        if bind is None:
            entries = [{"binding": 0, "resource": {"buffer": self._overlay_params[kind], "offset": 0, "size": 96}}]
            for i, buf in ((1, mesh.positions), (2, mesh.faces), (3, items)):
                entries.append({"binding": i, "resource": {"buffer": buf, "offset": 0, "size": buf.size}})
            bind = self._mesh_binds[kind] = self.ctx.device.create_bind_group(
                layout=self.pipelines.overlay_layout, entries=entries)
        return bind

    def _spread_order(self, src) -> np.ndarray:
        """The source's surfels, best spread first (:func:`gma.render.subset.spread_order`), made once."""
        key = (id(src), src.surfels.count)
        if self._spread is None or self._spread[:2] != key:
            binding = getattr(src, "binding", None)
            faces = None if binding is None else np.asarray(binding.face_id)
            self._spread = (*key, spread_order(src.surfels.count, faces))
        return self._spread[2]

    def _set_background(self, rgb) -> None:
        value = tuple(float(c) for c in rgb[:3])
        if value != self._background_value:
            self.ctx.write(self._background, np.array(value + (1.0,), np.float32))
            self._background_value = value

    # -- drawing ---------------------------------------------------------------------------------------
    @staticmethod
    def view_key(scene: Scene, camera: Camera) -> tuple:
        """Everything the surfel image depends on: equal keys give equal images."""
        opts, src = scene.options, scene.source
        return (id(src), src.version, camera.viewmat.tobytes(), camera.K.tobytes(), camera.width, camera.height,
                tuple(opts.background), opts.surfels)

    def draw(self, scene: Scene, camera: Camera, target: wgpu.GPUTextureView, target_format: str,
             lines: list[np.ndarray] | None = None, timer=None, images: list[ScreenImage] | None = None,
             quality: FrameQuality | None = FULL, complete: bool = False) -> None:
        """Draw ``scene`` seen by ``camera`` into ``target`` (a texture view of ``camera``'s size and
        ``target_format``). ``lines``: screen-space polylines [P, 2] in pixels; ``images``: quads drawn
        over everything (:class:`ScreenImage`); ``timer``: a :class:`gma.view.timing.FrameTimer` on
        sampled frames. ``quality``: how to draw the surfels (:class:`FrameQuality`); None shows the
        previous full frame's surfel image again when :meth:`view_key` is unchanged, and draws a full
        frame otherwise. ``complete``: check a full frame for surfels dropped to the intersection capacity
        and redraw it if any were (a 4-byte read that waits for the frame; always done for a source's
        first full frame). Overlays are drawn every frame."""
        ctx, opts, src = self.ctx, scene.options, scene.source
        w, h = camera.width, camera.height
        key = self.view_key(scene, camera)
        reuse = quality is None and self._drawn == (key, FULL) and self._image is not None
        if reuse and not self._drawn_checked and self._dropped_work():
            reuse = False  # the full frame on screen lost surfels to the capacity: draw it again, complete
        quality = quality or FULL
        if opts.surfels and not reuse:
            self._draw_surfels(scene, camera, quality, key, timer)
            must_check = complete or id(src) not in self._checked_sources
            if quality.is_full and must_check and self._dropped_work():
                self._draw_surfels(scene, camera, quality, key, None)
                self._drawn_checked = True  # drawn again with the capacity the same view just needed
            if quality.is_full:
                self._checked_sources.add(id(src))
            if not self._drawn_checked and self.frames % self.capacity_every == 0:
                self._dropped_work()  # frames in motion only adapt the capacity; they are not redrawn
        else:
            self._encode_pose(src, None, None, timer)
        self.frames += 1
        self._ensure_depth(w, h)
        enc = ctx.device.create_command_encoder(label="viewer.overlay")
        rp = enc.begin_render_pass(
            color_attachments=[{"view": target, "clear_value": (*opts.background[:3], 1.0),
                                "load_op": wgpu.LoadOp.clear, "store_op": wgpu.StoreOp.store}],
            depth_stencil_attachment={"view": self._depth_view, "depth_clear_value": 1.0,
                                      "depth_load_op": wgpu.LoadOp.clear, "depth_store_op": wgpu.StoreOp.discard},
            timestamp_writes=timer.writes("overlay") if timer else None,
        )
        if opts.surfels:
            exact = self._image_size == (w, h)
            rp.set_pipeline(self.pipelines.get("blit" if exact else "blit_scaled", target_format))
            rp.set_bind_group(0, self._blit_bind if exact else self._blit_scaled_bind)
            rp.draw(3)
        mesh = src.mesh
        want_sel = opts.selection and len(scene.selection) > 0
        if mesh is not None and (opts.wireframe or opts.normals or opts.coarse or want_sel):
            self._draw_mesh_overlays(rp, scene, camera, target_format, mesh)
        for slot, img in enumerate(images or []):
            self._draw_image(rp, slot, img, w, h, target_format)
        if lines:
            self._draw_lines(rp, lines, w, h, target_format)
        rp.end()
        if timer:
            timer.resolve(enc)
        ctx.submit(enc)

    def _encode_pose(self, src, quality: FrameQuality | None, order, timer):
        """Pose the source (when its pose changed) and, for a cheaper frame, thin its surfels; returns the
        surfel buffers to draw."""
        enc = self.ctx.device.create_command_encoder(label="viewer.pose")
        if timer:
            timer.mark(enc, "pose.begin")
        src.encode_update(enc)
        surfels = src.surfels
        if quality is not None:
            surfels = self.subset.encode(enc, src.surfels, quality.stride, order)
        if timer:
            timer.mark(enc, "pose.end")
        self.ctx.submit(enc)
        return surfels

    def _draw_surfels(self, scene: Scene, camera: Camera, quality: FrameQuality, key, timer) -> None:
        """Pose and render the surfel image of ``quality`` into ``self._image``."""
        src = scene.source
        order = self._spread_order(src) if quality.stride > 1 else None
        surfels = self._encode_pose(src, quality, order, timer)
        self._set_background(scene.options.background)
        image_size = quality.image_size(camera.width, camera.height)
        self._ensure_image(*image_size)
        self._drawn_capacity = self.rasterizer.isect_capacity_hint
        self.last_state = self.rasterizer.render_to_texture(surfels, camera.resized(*image_size),
                                                            self._image_view, self._background, timer)
        self._drawn = (key, quality)
        self._drawn_checked = False
        self.surfel_frames += 1

    def _dropped_work(self) -> bool:
        """Whether the last surfel image needed more intersections than it was drawn with (reads 4 bytes and
        raises the capacity hint to what it needed)."""
        if self.last_state is None:
            self._drawn_checked = True
            return False
        needed = self.rasterizer.needed_capacity(self.last_state)
        self.rasterizer.reserve_capacity(needed)
        self._drawn_checked = needed <= self._drawn_capacity
        return not self._drawn_checked

    def _draw_mesh_overlays(self, rp, scene: Scene, camera: Camera, fmt: str, mesh) -> None:
        opts = scene.options
        self._ensure_mesh(scene)
        lo, hi = scene.source.bounds()
        eye = -camera.viewmat[:3, :3].T @ camera.viewmat[:3, 3]
        # Near/far from the distance to the body's box, for depth precision (with generous margins).
        reach = float(np.linalg.norm(np.maximum(np.abs(lo - eye), np.abs(hi - eye)))) + 1.0
        mvp = clip_matrix(camera, 0.01, 2.0 * reach)

        def draw(kind, color, count, items):
            settings = (opts.normal_length, opts.coarse_radius, 2e-4, 0.0)
            data = np.concatenate([mvp.T.reshape(-1), np.asarray(color, np.float32), settings]).astype(np.float32)
            self.ctx.write(self._overlay_params[kind], data)
            rp.set_pipeline(self.pipelines.get(kind, fmt))
            rp.set_bind_group(0, self._mesh_bind(kind, mesh, items))
            rp.draw(count)

        nf = mesh.num_faces
        if opts.coarse:
            draw("coarse", (1, 1, 1, 1), 6 * nf, self._edges_buf)
        draw("depth", (0, 0, 0, 0), 3 * nf, self._edges_buf)
        if opts.selection and self._num_sel:
            draw("highlight", opts.highlight_color, 3 * self._num_sel, self._sel_buf)
        if opts.wireframe:
            draw("wire", opts.wire_color, 2 * self._num_edges, self._edges_buf)
        if opts.normals:
            draw("normals", opts.normal_color, 2 * nf, self._edges_buf)

    def _draw_lines(self, rp, lines, w, h, fmt) -> None:
        self.ctx.write(self._lines_params, np.array([w, h, 0, 0, 1.0, 0.85, 0.0, 1.0], np.float32))
        bind = self.ctx.device.create_bind_group(layout=self.pipelines.lines_layout, entries=[
            {"binding": 0, "resource": {"buffer": self._lines_params, "offset": 0, "size": 32}}])
        rp.set_pipeline(self.pipelines.get("lines", fmt))
        rp.set_bind_group(0, bind)
        for line in lines:
            pts = np.asarray(line, np.float32).reshape(-1, 2)
            if len(pts) < 2:
                continue
            vb = self.ctx.upload(pts, "viewer.lines.vertices", wgpu.BufferUsage.VERTEX | wgpu.BufferUsage.COPY_DST)
            rp.set_vertex_buffer(0, vb)
            rp.draw(len(pts))

    def _draw_image(self, rp, slot: int, img: ScreenImage, w: int, h: int, fmt: str) -> None:
        dev = self.ctx.device
        entry = self._images.get(slot)
        if entry is None or entry[0] != img.key:
            data = np.asarray(img.image)
            if data.dtype != np.uint8:
                data = (np.clip(data, 0, 1) * 255 + 0.5).astype(np.uint8)
            ih, iw = data.shape[:2]
            tex = dev.create_texture(size=(iw, ih, 1), format=wgpu.TextureFormat.rgba8unorm,
                                     usage=wgpu.TextureUsage.TEXTURE_BINDING | wgpu.TextureUsage.COPY_DST,
                                     label="viewer.screen_image")
            dev.queue.write_texture({"texture": tex}, np.ascontiguousarray(data),
                                    {"bytes_per_row": 4 * iw, "rows_per_image": ih}, (iw, ih, 1))
            params = entry[3] if entry else self.ctx.buffer(16, f"viewer.image{slot}", UNIFORM)
            vbuf = entry[4] if entry else self.ctx.buffer(96, f"viewer.image{slot}.vertices",
                                                          wgpu.BufferUsage.VERTEX | wgpu.BufferUsage.COPY_DST)
            bind = dev.create_bind_group(layout=self.pipelines.image_layout, entries=[
                {"binding": 0, "resource": {"buffer": params, "offset": 0, "size": 16}},
                {"binding": 1, "resource": tex.create_view()},
                {"binding": 2, "resource": self._linear()}])
            entry = self._images[slot] = (img.key, tex, bind, params, vbuf)
        _, _, bind, params, vbuf = entry
        c = np.asarray(img.corners, np.float32).reshape(4, 2)
        uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
        quad = np.concatenate([c, uv], 1)[[0, 1, 2, 0, 2, 3]]
        self.ctx.write(vbuf, quad.astype(np.float32))
        self.ctx.write(params, np.array([w, h, img.opacity, 0], np.float32))
        rp.set_pipeline(self.pipelines.get("image", fmt))
        rp.set_bind_group(0, bind)
        rp.set_vertex_buffer(0, vbuf)
        rp.draw(6)

    # -- offscreen -------------------------------------------------------------------------------------
    def render_image(self, scene: Scene, camera: Camera, complete: bool = True, lines=None, images=None
                     ) -> np.ndarray:
        """Draw offscreen and read the result back: [H, W, 4] uint8 RGBA. With ``complete`` the frame is
        redrawn once if the intersection capacity had to grow (so no surfel is dropped)."""
        w, h = camera.width, camera.height
        if self._offscreen is None or self._offscreen.size[:2] != (w, h):
            self.ctx.check_image_size(w, h, "the image")
            self._offscreen = self.ctx.device.create_texture(
                size=(w, h, 1), format=OFFSCREEN_FORMAT,
                usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC, label="viewer.offscreen")
        view = self._offscreen.create_view()
        self.draw(scene, camera, view, OFFSCREEN_FORMAT, lines=lines, images=images, complete=complete)
        return read_texture(self.ctx, self._offscreen)


def read_texture(ctx: GpuContext, texture) -> np.ndarray:
    """[H, W, 4] uint8 copy of a 4-byte-per-pixel texture (BGRA formats are swapped to RGBA)."""
    w, h = texture.size[0], texture.size[1]
    raw = ctx.device.queue.read_texture({"texture": texture, "origin": (0, 0, 0), "mip_level": 0},
                                        {"offset": 0, "bytes_per_row": 4 * w, "rows_per_image": h}, (w, h, 1))
    img = np.frombuffer(raw, np.uint8).reshape(h, w, 4).copy()
    if str(texture.format).startswith("bgra"):
        img = img[..., [2, 1, 0, 3]]
    return img
