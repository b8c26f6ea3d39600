"""The Python host, in the order data flows: scene (load + validate) -> compile (device
arrays) -> render (device, integrator, film, outputs) -> uq (realization statistics) and
figures (sample figures) -> distributed (render and uq on a Dask cluster); beside them gp
(the GP model), io (file formats), schema (the declarative scene schema),
kinds (one table per extension axis), layout (host/device structs) and errors. Each
package's docstring says what it may import; tests/test_layering.py checks it.
gpiscl/api.py sits on top, and gpiscl/cli/ on it."""
