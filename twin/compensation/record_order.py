"""The canonical order of training records: a model that does not depend on the order its files were given in.

``twin train a.csv b.csv`` and ``twin train b.csv a.csv`` stack the same rows,
but a fit is not blind to their order: the seeded FCM start of ANFIS, the
random start of an ANN, the rolling-origin folds of ``--select auto`` (train
on the blocks before, test on the next) and the record whose start a model
file keeps as its training reference all follow the stacking order. So the
records are put in one order that depends on their content only
(:func:`canonical_key`):

1. the first time stamp, s — records on one clock (date-time stamps, or
   ``time_s`` that runs on from file to file) stand in time order, so a file
   that continues another follows it, and rolling origin forecasts into the
   later record;
2. then a SHA-256 digest of the times and of the readings of the model's
   channels, for records whose clocks each start at 0 (twin runs, a
   ``time_s`` that restarts per file), which have no time order of their own.

Not the file name or its path: a user who renames or moves a file gets the
same model (the records' labels, which come from the file names, change with
them; labels are for tables, never for the order). Records of equal content
are interchangeable for the fit; their label breaks the tie, so that a
repeated label's ``_2`` goes to the same one each time.
"""
from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np

from ..core.dataset import Dataset


def content_digest(dataset: Dataset, names: Sequence[str]) -> str:
    """SHA-256 of a record's times (s) and readings of ``names`` (in the record's units), as hex.

    The name of the file, its folder and the record's label play no part. A missing reading (NaN) and
    −0.0 hash alike however they were written.

    Parameters
    ----------
    dataset : Dataset
        A record.
    names : sequence of str
        The channels that make its content for a model (inputs, observed thermometers, target); those the
        record lacks are skipped (the fit names them).

    Returns
    -------
    str
        64 hex digits.
    """
    present = [name for name in names if name in dataset]
    table = np.column_stack([dataset.time_s, dataset.matrix(present)]) if present else dataset.time_s[:, None]
    missing = ~np.isfinite(table)
    # + 0.0 turns -0.0 into 0.0; NaN payloads differ by writer, so a fixed value and the mask stand for them
    readings = np.where(missing, 0.0, table) + 0.0
    digest = hashlib.sha256()
    digest.update(np.asarray(table.shape, np.int64).tobytes())
    digest.update(np.ascontiguousarray(readings, dtype="<f8").tobytes())
    digest.update(np.packbits(missing).tobytes())
    return digest.hexdigest()


def canonical_key(dataset: Dataset, names: Sequence[str]) -> tuple[float, str]:
    """``(first time stamp in s, content digest)``: a record's place in the canonical order (module docstring).

    Parameters
    ----------
    dataset : Dataset
        A record (one without rows comes last).
    names : sequence of str
        The model's channels (see :func:`content_digest`).

    Returns
    -------
    tuple of (float, str)
    """
    start_s = float(dataset.time_s[0]) if len(dataset) else float("inf")   # an empty record: the fit names it
    return start_s, content_digest(dataset, names)


def in_canonical_order(datasets: Sequence[Dataset], names: Sequence[str]) -> list[Dataset]:
    """The records sorted by :func:`canonical_key`, ties of equal content by label, then source file.

    Parameters
    ----------
    datasets : sequence of Dataset
        Records in the order given.
    names : sequence of str
        The model's channels.

    Returns
    -------
    list of Dataset
        The same records (not copies), in an order that no permutation of ``datasets`` changes.
    """
    from .records import dataset_label   # records builds on this module

    keyed = [(canonical_key(ds, names), dataset_label(ds), str(ds.metadata.get("source") or ""), k)
             for k, ds in enumerate(datasets)]
    return [datasets[k] for *_, k in sorted(keyed)]
