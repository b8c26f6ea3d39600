"""Figures of random geometry for `gpiscl sample` (samples). Imports compile, scene, gp
and below; only the API imports it."""
