"""The Python host, in the order data flows: scene (load + validate) -> compile (device
arrays) -> render (device, integrator, film, outputs) -> commands (uq, figures); beside
them gp (the GP model and numpy twins), io (file formats), schema (the declarative scene
schema), kinds (one table per extension axis), layout (host/device structs) and errors. Each package's docstring says what it may import; tests/test_layering.py
checks it."""
