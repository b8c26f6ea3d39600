"""Rendering on a Dask cluster, bit-identical to a local render (cluster). Imports uq,
render and below; only the API imports it, and only when asked for a cluster."""
