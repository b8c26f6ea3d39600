"""The scene format: strict records (schema), shapes, lights, GPIS blocks, loading, the
resolved output, and the Tungsten importer. Imports gp, io, layout, errors; never compile
or render."""
