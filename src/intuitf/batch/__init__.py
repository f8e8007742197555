"""``intuitf batch``: one visual standard across a whole collection of volumes.

A reference (a picture, a TF, or a finished run) sets the look; every volume gets its own run,
seeded with the reference TF carried over to it by matching histogram materials, and searched
against the reference picture. Runs go on a local process pool or on Ray, share one budget,
resume after a kill, and end in a summary that flags the volumes far from the reference.

- :mod:`~intuitf.batch.plan`: volumes from files, folders, globs and DICOM series;
- :mod:`~intuitf.batch.reference`: the reference and the similarity to it;
- :mod:`~intuitf.batch.transfer`: carrying a TF to another volume by its materials;
- :mod:`~intuitf.batch.budget`: the shared budget (ledger, SharedBudget);
- :mod:`~intuitf.batch.runner`: workers, the pool and Ray backends, the driver;
- :mod:`~intuitf.batch.summary`: summary.json, the table, contact sheet and report;
- :mod:`~intuitf.batch.job`: all of it as one call, :func:`run_batch`.
"""

from __future__ import annotations

from intuitf.batch.job import BatchJob, BatchRequest, run_batch
from intuitf.batch.plan import VolumeItem, plan_volumes
from intuitf.batch.transfer import transfer_tf

__all__ = ["BatchJob", "BatchRequest", "VolumeItem", "plan_volumes", "run_batch", "transfer_tf"]
