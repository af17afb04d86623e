"""velogauss_ref: the readable NumPy reference of every VeloGauss equation.

One function per spec ID (spec/index.toml maps each ID to its function here). Written to
be read beside spec/*.md; gradients come from the `autograd` package. Slow on purpose,
exact on purpose: this is the oracle the fast PyTorch path is tested against.
"""
