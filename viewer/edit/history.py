"""History and file: undo, redo, revert to a record, the unsaved-edits mark, save (atomic, with the
history), and the folding of a brush stroke's records into one."""

from __future__ import annotations

from pathlib import Path

import torch

from gma.core.errors import InputError
from gma.edit import EditError
from gma.edit.editor import summarize
from gma.edit.history import make_record, record_face_ids, record_old

__all__ = ["HistoryTools", "merge_records"]


class HistoryTools:
    """The history and file part of :class:`viewer.edit.EditTools`."""

    def _init_history(self) -> None:
        self.saved_mark = self._history_mark()  # the history as last saved (or opened)

    def _history_mark(self) -> tuple:
        """What identifies the avatar's state: its history's length and newest record (undo back to the
        saved state restores both, so the file is clean again; any new edit adds or replaces a record)."""
        history = self.avatar.history if self.avatar is not None else []
        return len(history), id(history[-1]) if history else None

    @property
    def dirty(self) -> bool:
        return self.avatar is not None and self._history_mark() != self.saved_mark

    @property
    def path(self) -> Path | None:
        return getattr(self.source, "path", None)

    def history(self) -> list[str]:
        """One line per history record, oldest first (as of the last applied edit)."""
        return [summarize(r) for r in self.avatar.history] if self.avatar is not None else []

    @property
    def can_undo(self) -> bool:
        return self.avatar is not None and bool(self.avatar.history)

    @property
    def can_redo(self) -> bool:
        return self._editor is not None and self._editor.can_redo

    # Undo / redo restore stored rows (no solve), so they run on this thread.
    def undo(self):
        self.wait()
        return self._now("undo", self.editor.undo)

    def redo(self):
        self.wait()
        return self._now("redo", self.editor.redo)

    def revert(self, index: int):
        """Undo back to the first ``index`` records (0: the avatar as fitted or first saved)."""
        self.wait()
        return self._now(f"revert to {index}", lambda: self.editor.revert(index))

    def save(self, path=None) -> Path:
        """Write the avatar (with its history) atomically to ``path`` (default: the file it came from)."""
        if self.avatar is None:
            raise InputError("nothing to save: this source is not an avatar")
        self.wait()
        target = Path(path) if path else self.path
        if target is None:
            raise InputError("save as: give a file name")
        if target.suffix.lower() != ".gma":
            raise InputError(f"{target}: an avatar file must end in .gma")
        if target.parent and not target.parent.is_dir():
            raise InputError(f"{target}: folder {target.parent} does not exist")
        try:
            self.avatar.save(target)
        except OSError as exc:
            raise InputError(f"cannot write {target}: {exc.strerror or exc}") from None
        self.source.path, self.source.name = target, target.name
        self.saved_mark = self._history_mark()
        self.state.message = f"saved {target} ({len(self.avatar.history)} history records)"
        return target


def merge_records(history: list[dict], start: int, params: dict) -> int:
    """Fold ``history[start:]`` (paint records of one stroke) into one record holding, for every face
    touched, its features from before the first dab: undoing it restores the stroke's start exactly.
    Returns the number of faces (0 when nothing was recorded)."""
    recs = history[start:]
    if not recs:
        return 0
    if len(recs) == 1:
        recs[0]["params"] = {**recs[0]["params"], **params}
        return int(recs[0].get("faces", 0))
    if any(r.get("op") != "paint" or "face_ids" not in r for r in recs):
        raise EditError("a stroke's history holds records other than paint")
    olds: dict[int, dict[str, torch.Tensor]] = {}
    for rec in reversed(recs):  # newest first, so the oldest value of each face wins
        ids, old = record_face_ids(rec), record_old(rec)
        for k, fid in enumerate(ids.tolist()):
            olds[fid] = {name: v[k] for name, v in old.items()}
    faces = torch.tensor(sorted(olds), dtype=torch.long)
    names = list(next(iter(olds.values())))
    old = {name: torch.stack([olds[f][name] for f in faces.tolist()]) for name in names}
    history[start:] = [make_record("paint", params, faces, old)]
    return len(faces)
