"""velogauss_core: what the NumPy reference, the torch fast path and the application share.

Constants (`constants`), the motion model's configuration and tables (`motion`), the LPIPS
network tables and weight files (`lpips_nets`) and the input checks on plain values and
NumPy arrays (`checks`). It imports neither autograd nor torch, so `velogauss_fast` and
`velogauss` depend on it, never on `velogauss_ref`, at run time (ARCHITECTURE.md).
"""
