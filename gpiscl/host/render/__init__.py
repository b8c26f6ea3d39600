"""Running a compiled scene: device and program builder, queues, the wavefront integrator
and its function-space stages, film and outputs. Imports compile and below."""
