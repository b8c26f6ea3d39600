"""The conductor presets now live with the rough_conductor kind (kinds/conductors.py);
this name stays for the Tungsten importer, which reads CONDUCTORS from here."""
from __future__ import annotations

from ..kinds.conductors import CONDUCTORS, eta_k

__all__ = ["CONDUCTORS", "eta_k"]
