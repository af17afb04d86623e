"""`velogauss view RUN`: a 4D viewer of a trained run in the browser, built on viser.

`frame` turns the browser's camera into a velogauss `Camera` and renders a frame with the
project's own rasterizer; `server` is the viser scene, its controls and one render thread per
browser tab; `command` is the command line. viser is the optional extra `velogauss[view]`.
"""
