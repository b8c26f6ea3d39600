"""Uncertainty quantification over GPIS realizations: the statistics (sums), the partial
files and outputs (files), the realization loop (realizations). Imports render and below;
distributed and the API import it."""
