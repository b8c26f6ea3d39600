"""Scene records to device arrays: BVH, camera, environment tables, GPIS objects (means,
kernels, proxies, SDF bakes, posterior tables, colour fields). Imports scene and below."""
