"""The AOVs asked for (N, P, id), each pixel's from the sample that Z reports."""
import numpy as np


class NearestAOVs:
    """N, P and id of each pixel's nearest hit among its samples: the sample
    whose depth Z reports, so that the AOVs agree with Z (and with A > 0)
    at partly covered edge pixels. 0, 0 and -1 where no sample hit. Only the
    AOVs asked for are kept."""

    def __init__(self, names, n_pix):
        self.names = names
        self.depth = np.full(n_pix, np.inf, np.float32)
        self.n = np.zeros((n_pix, 3), np.float32) if "N" in names else None
        self.p = np.zeros((n_pix, 3), np.float32) if "P" in names else None
        self.prim = np.full(n_pix, -1.0, np.float32) if "id" in names else None

    def add(self, surface):
        """Take this pass's samples that are nearer than what each pixel has."""
        nearer = surface.depth < self.depth[surface.pixel]
        pix = surface.pixel[nearer]
        self.depth[pix] = surface.depth[nearer]
        if self.n is not None:
            self.n[pix] = surface.smooth_n[:, nearer].T
        if self.p is not None:
            self.p[pix] = surface.point[:, nearer].T
        if self.prim is not None:
            self.prim[pix] = surface.prim[nearer]

    def channels(self, height, width):
        out = {}
        for name, values in (("N", self.n), ("P", self.p)):
            if values is not None:
                for i, c in enumerate("XYZ"):
                    out[f"{name}.{c}"] = values[:, i].reshape(height, width)
        if self.prim is not None:
            out["id"] = self.prim.reshape(height, width)
        return out
