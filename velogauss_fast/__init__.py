"""velogauss_fast: the PyTorch twin of velogauss_ref (same module and function names).

Runs on CPU and CUDA in float32 and float64; all training runs on it.
"""
