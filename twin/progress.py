"""A tqdm progress bar behind the ``progress(done, total)`` callbacks of long work."""
from __future__ import annotations


def progress_bar(description):
    from tqdm import tqdm

    bar = {"tqdm": None}

    def update(done, total):
        if bar["tqdm"] is None:
            bar["tqdm"] = tqdm(total=total, desc=description, unit="sample", leave=False, mininterval=0.5)
        bar["tqdm"].n = done
        bar["tqdm"].refresh() if done == total else bar["tqdm"].update(0)
        if done == total:
            bar["tqdm"].close()

    return update


