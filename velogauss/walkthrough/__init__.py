"""An executable walkthrough of the spec: every equation ID, run through the reference.

`python -m velogauss.walkthrough --out DIR` (or `velogauss walkthrough --out DIR`)
writes `DIR/walkthrough.md` and `DIR/figures/*.png`: for each ID of spec/index.toml, in
order, the spec's own text, the reference function that implements it, a small example
with its printed numbers and, where a picture says more, a figure. The committed copy is
`docs/`; tests/app/test_walkthrough.py regenerates it and compares the text.

One module per part of the spec (gaussians, screen, blending, networks, fields,
integration, deformation, physics, losses_metrics), plus the shared machinery: spec_text
(reading the spec), printing (numbers), figures (matplotlib, Agg), setups (the examples'
inputs), files (atomic writes) and build (assembling the document). NumPy only: nothing
here imports torch.
"""

from velogauss.walkthrough.build import write_walkthrough

__all__ = ["write_walkthrough"]
