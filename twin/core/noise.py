"""Measurement models of the virtual sensors: offsets, noise and resolution, drawn from a seed.

- DS18S20 digital thermometer: a constant offset per sensor, uniform in ±0.5 °C
  (its accuracy), and readings quantised to its 0.0625 °C resolution.
- NCDT eddy-current displacement sensor: white noise of 0.05 µm rms and
  quantisation to its 0.1 µm resolution.
- FBG strain line: white noise of 0.2 µε rms and 0.1 µε resolution.
- S65 thermal camera: one absolute offset per camera within ±2 °C (its
  accuracy), 0.08 °C rms pixel noise (its sensitivity).
Values are in the channels' edge units (°C, µm, µε).
"""
from __future__ import annotations

import numpy as np

MODELS = {
    "DS18S20": {"offset_per_sensor": 0.5, "noise": 0.0, "resolution": 0.0625},
    "NCDT": {"offset_per_sensor": 0.0, "noise": 0.05, "resolution": 0.1},
    "FBG": {"offset_per_sensor": 0.0, "noise": 0.2, "resolution": 0.1},
    "S65": {"offset_common": 2.0, "noise": 0.08, "resolution": 0.0},
}
#: Which scenario noise setting applies to which channel kind.
KIND_SETTING = {"temperature": "temperature", "air": "temperature", "displacement": "displacement",
                "strain": "strain", "camera": "camera"}


def apply_noise(values: np.ndarray, kinds: list[str], settings: dict[str, str], seed: int) -> np.ndarray:
    """Noisy copies of sensor values: per-sensor and common offsets, white noise, resolution.

    The same seed gives the same offsets and noise; channels of kinds whose
    setting is ``none`` are returned unchanged.

    Parameters
    ----------
    values : ndarray, shape (n_times, n_channels)
        Exact values in the channels' units (°C, µm, µε).
    kinds : list of str
        Kind of each channel (``temperature``, ``air``, ``displacement``, ``strain``, ``camera``).
    settings : dict of str to str
        The scenario's ``[noise]`` table: setting → sensor model name (see :data:`MODELS`).
    seed : int
        Seed of the random generator.

    Returns
    -------
    ndarray, shape (n_times, n_channels)
        The noisy values.
    """
    rng = np.random.default_rng(seed)
    out = np.array(values, dtype=float, copy=True)
    n = out.shape[0]
    for kind, setting in KIND_SETTING.items():
        model_name = settings.get(setting, "none")
        cols = [j for j, k in enumerate(kinds) if k == kind]
        if model_name == "none" or not cols:
            continue
        model = MODELS[model_name]
        block = out[:, cols]
        if model.get("offset_per_sensor"):
            block += rng.uniform(-1, 1, size=len(cols)) * model["offset_per_sensor"]
        if model.get("offset_common"):
            block += rng.uniform(-1, 1) * model["offset_common"]
        if model.get("noise"):
            block += rng.normal(0.0, model["noise"], size=(n, len(cols)))
        if model.get("resolution"):
            block = np.round(block / model["resolution"]) * model["resolution"]
        out[:, cols] = block
    return out
