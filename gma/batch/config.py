"""What a batch does (:class:`BatchConfig`, saved as ``OUT/batch.json``) and who it does it for
(:class:`Person`, one per input video or sequence, each with its own folder ``OUT/<name>/``)."""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path

from gma.avatar.config import doc
from gma.core.errors import InputError, MissingFileError

__all__ = ["ALL_STEPS", "BatchConfig", "Person", "find_people"]

# In the order a person goes through them; gma.batch.steps holds one function per name.
ALL_STEPS = ("import", "fit", "eval", "export", "video")


@dataclass
class BatchConfig:
    """Everything ``gma batch`` does besides the fit itself (the fit is a :class:`gma.train.FitConfig`,
    saved beside this in ``batch.json``)."""

    steps: tuple[str, ...] = doc(ALL_STEPS, "steps per person, in this order")
    train_decoders: int = doc(0, "shared decoders: train them on the first N people (phase 1), then fit only the "
                                 "features of everyone else against them (phase 2); 0: each its own decoders")
    address: str = doc("", "Ray cluster to join ('auto', 'ray://host:port'); empty: a local runtime here")
    cpus_per_task: float = doc(1.0, "CPU cores Ray reserves per person (the fit itself uses FitConfig.threads)")
    gpus_per_task: float = doc(0.0, "GPUs Ray reserves per person (0.25: four people share one GPU)")
    eval_resolution: int = doc(512, "longest image side of the evaluation (as gma eval)")
    video_size: int = doc(256, "turntable video frame size in pixels")
    video_frames: int = doc(72, "turntable video frames (one full turn)")
    export_format: str = doc("3dgs", "export step: splat PLY layout (3dgs or 2dgs) of the canonical pose")

    def __post_init__(self):
        self.steps = tuple(self.steps)
        unknown = [s for s in self.steps if s not in ALL_STEPS]
        if unknown or not self.steps:
            raise InputError(f"--steps {','.join(self.steps)}: unknown step(s) {unknown}; choose from "
                             f"{','.join(ALL_STEPS)}")
        if self.train_decoders < 0 or self.cpus_per_task < 0 or self.gpus_per_task < 0:
            raise InputError("--train-decoders, --cpus-per-task and --gpus-per-task must be >= 0")
        if self.video_size < 16 or self.video_frames < 1:
            raise InputError("--video-size must be >= 16 and --video-frames >= 1")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["steps"] = list(self.steps)
        return d


@dataclass(frozen=True)
class Person:
    """One input: a video file (imported into ``OUT/<name>/sequence``) or a sequence folder (used in place)."""

    name: str
    source: str  # absolute path of the video or sequence folder
    kind: str  # "video" or "sequence"

    def folder(self, out: Path) -> Path:
        return Path(out) / self.name

    def sequence(self, out: Path) -> Path:
        return Path(self.source) if self.kind == "sequence" else self.folder(out) / "sequence"

    def avatar(self, out: Path) -> Path:
        return self.folder(out) / "avatar.gma"

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _name(path: Path) -> str:
    # Folder names on every filesystem; "_" first is kept for the batch's own folders (OUT/_shared).
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", path.stem if path.is_file() else path.name).strip("._") or "person"
    return name.lstrip("_") or "person"


def find_people(inputs: list[str]) -> list[Person]:
    """One :class:`Person` per input, in order; names are the file or folder names, numbered when two
    collide. A folder must be a sequence (holds ``cameras.json``); anything else is taken as a video.
    Raises :class:`MissingFileError` / :class:`InputError` naming the input."""
    people: list[Person] = []
    seen: dict[str, int] = {}
    sources: set[str] = set()
    for text in inputs:
        path = Path(text).expanduser().resolve()
        if not path.exists():
            raise MissingFileError(f"{text}: not found")
        if path.is_dir() and not (path / "cameras.json").is_file():
            raise InputError(f"{text}: a folder but not a sequence (no cameras.json); give sequences or videos")
        if str(path) in sources:
            raise InputError(f"{text}: given twice")
        sources.add(str(path))
        name = _name(path)
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            name = f"{name}_{seen[name]}"
        people.append(Person(name, str(path), "sequence" if path.is_dir() else "video"))
    if not people:
        raise InputError("no videos or sequences given")
    return people

