"""Many people at once (``gma batch``): one task per person through the single-person library calls
(video import, fit, evaluation, export, a turntable video), scheduled by Ray on a laptop or a cluster.

The per-person work (:mod:`gma.batch.task`) does not import Ray, so it runs and is tested without it;
only :mod:`gma.batch.runner` needs the optional extra ``gma[cluster]``.
"""

from gma.batch.config import BatchConfig, Person, find_people
from gma.batch.summary import write_summary

__all__ = ["BatchConfig", "Person", "find_people", "write_summary"]
