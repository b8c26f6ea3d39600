"""Stand-ins for the openvdb objects the VDB converter reads (the module is not a
dependency and cannot be installed from PyPI), so its logic runs in every test run."""
import numpy as np


class FakeTransform:
    def __init__(self, voxel, offset):
        self.voxel, self.offset = voxel, np.asarray(offset, float)

    def voxelSize(self):
        return (self.voxel,) * 3

    def indexToWorld(self, ijk):
        return tuple(self.offset + self.voxel * np.asarray(ijk, float))


class FakeGrid:
    """OpenVDB's FloatGrid surface: sparse voxels, a background, copyToArray."""

    def __init__(self, name, voxels: dict, background, voxel, offset):
        self.name, self.voxels, self.background = name, voxels, background
        self.transform = FakeTransform(voxel, offset)

    def evalActiveVoxelBoundingBox(self):
        ijk = np.array(list(self.voxels))
        return tuple(ijk.min(0)), tuple(ijk.max(0))

    def copyToArray(self, array, ijk):
        for (i, j, k), value in self.voxels.items():
            array[i - ijk[0], j - ijk[1], k - ijk[2]] = value
