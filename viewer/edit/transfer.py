"""The transfer tool: a donor avatar that shares this one's decoders, shown as a thumbnail, whose
features (geometry, texture or both) are copied onto the selected faces."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gma.core.errors import InputError

__all__ = ["TransferTools"]


class TransferTools:
    """The transfer part of :class:`viewer.edit.EditTools`."""

    def _init_transfer(self) -> None:
        self.donor = None  # the donor Avatar of a transfer
        self.donor_name = ""
        self.donor_thumbnail: np.ndarray | None = None  # [h, w, 4] uint8 render of the donor
        self.transfer_what = "tex"

    def load_donor(self, path):
        """Open a donor avatar; refused (with what differs) when it does not share this one's decoders."""
        from gma.avatar import Avatar
        from gma.edit import check_shared_decoders

        path = Path(path)
        self.wait()
        try:
            donor = Avatar.load(path, self.body)
        except FileNotFoundError as exc:
            raise InputError(str(exc)) from None
        check_shared_decoders(self.editor.model, donor.model, self.path.name if self.path else "this avatar",
                              path.name)
        self.donor, self.donor_name = donor, path.name
        self.donor_thumbnail = self._thumbnail(donor)
        self.state.message = f"donor {path.name} loaded: select faces, choose geo / tex / both, transfer"
        return donor

    def _thumbnail(self, donor, size: int = 128) -> np.ndarray:
        """A small front render of the donor, drawn once (shown in a corner of the frame)."""
        from gma.view import BodySource, FrameRenderer, OrbitCamera, Scene

        dec = donor.decode("fine")
        src = BodySource(self.state.ctx, self.body, dec.binding, dec.colors.numpy(), dec.opacities.numpy(),
                         name=self.donor_name, vertex_offsets=dec.vertex_offsets)
        src.set_params({"shape": donor.shape})
        cam = OrbitCamera.framing(*src.bounds(), up_axis=src.up_axis).camera(size, size)
        scene = Scene(src)
        scene.options.background = self.state.scene.options.background
        return FrameRenderer(self.state.ctx).render_image(scene, cam)

    def transfer(self):
        """Copy the donor's features (``transfer_what``: geo, tex, both) onto the selected faces."""
        if self.donor is None:
            raise InputError("no donor avatar: open one in the Transfer section (or drop a .gma on the window)")
        sel, what, editor, donor = self.selection.require(), self.transfer_what, self.editor, self.donor
        name = self.path.name if self.path else "target"
        return self._run(f"transfer {what}", lambda: editor.transfer(donor, sel, what, donor_name=self.donor_name,
                                                                     target_name=name))
