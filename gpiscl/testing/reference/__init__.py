"""Independent numpy twins of device code, used as oracles: the camera model
(camera.py) and the rough conductor BSDF (rough_conductor.py)."""
