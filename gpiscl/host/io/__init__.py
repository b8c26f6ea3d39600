"""File formats: images (EXR, PNG, tonemaps), grid .npz files, meshes, point files, VDB
conversion. Imports gp and errors only: what it reads, the scene layer validates."""
