"""Kind tables: one per extension axis (materials, lights, GP kernels, means, memory
models, colour fields). A kind is declared once, in Python, with its scene schema, device
id, traits and the one device file that implements it; the table generates the scene
schema's variants, the C enumeration, the trait predicates and the device dispatch
(docs/extending.md walks through adding one).

May import: errors, gp, io and schema (a declaration names its host class and its
fields); imported by layout, scene, compile and render.
"""
