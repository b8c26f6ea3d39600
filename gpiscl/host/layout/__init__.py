"""Structs shared by host and device, each defined once (numpy dtype + C declaration):
scene records, queues, GP records, function-space records. Imports gp and errors only."""
