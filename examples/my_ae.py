import numpy as np


class MyAE:
    """Drive the mean of the raw 12-bit image towards ``target`` of full scale (4095 DN)."""

    name = "my-ae"

    def __init__(self, target=0.4, gain=1.0):
        self.target, self.gain = float(target), float(gain)

    def reset(self):
        pass

    def next_exposure(self, raw: np.ndarray, exposure_ms: float) -> float:
        mean = max(float(raw.mean()) / 4095.0, 1e-3)  # raw: H x W uint16 Bayer, read-only
        return float(exposure_ms * (self.target / mean) ** self.gain)
