"""Walkthrough part: the two network building blocks (VG-ENC, VG-MLP)."""

import numpy as np

from velogauss_core.motion import mlp_layers
from velogauss_ref.nn import mlp, positional_encoding
from velogauss.walkthrough.figures import new_figure, save
from velogauss.walkthrough.printing import Section, session


def encoding_section(figures):
    """VG-ENC: gamma of a 2-vector with two frequencies; the components of gamma over x."""
    x = np.array([[0.25, -0.5]])
    return Section(
        "Small MLPs struggle to represent functions that vary quickly with their input; feeding them "
        "sines and cosines of the input at doubling frequencies (γ, as in NeRF) fixes that. The raw "
        "input comes first, then one sin/cos pair per frequency. The time input of the coefficient "
        "network uses no frequencies (`n_freqs_t = 0`): sinusoids of `t` would repeat periodically "
        "into the future, exactly where VeloGauss extrapolates.",
        [session({"x": x}, "positional_encoding(x, n_freqs=2)  # x, sin(πx), cos(πx), sin(2πx), cos(2πx)",
                 {"gamma": positional_encoding(x, 2)}),
         _encoding_figure(figures)],
    )


def _encoding_figure(figures):
    x = np.linspace(-1, 1, 401)[:, None]
    gamma = positional_encoding(x, 3)
    fig = new_figure(8, 2.8)
    ax = fig.subplots()
    ax.plot(x[:, 0], gamma[:, 0], color="k", label="x")
    for k in range(3):
        ax.plot(x[:, 0], gamma[:, 1 + 2 * k], color=f"C{k}", label=f"sin(2^{k} πx)")
        ax.plot(x[:, 0], gamma[:, 2 + 2 * k], color=f"C{k}", linestyle="--", label=f"cos(2^{k} πx)")
    ax.set(xlabel="x", ylabel="γ(x) component")
    ax.legend(ncol=4, fontsize=7, loc="lower center")
    return save(fig, figures, "enc-gamma", "The seven components of positional_encoding(x, 3) for a scalar x.")


def mlp_section(figures):
    """VG-MLP: a 2 -> 4 -> 1 network at three inputs, one far into silu's tails."""
    layers = mlp_layers(np.random.default_rng(0), 2, 4, 1, 1)
    x = np.array([[0.0, 0.0], [1.0, -1.0], [-20.0, 40.0]])
    return Section(
        "Every network of the motion model is a plain MLP whose parameters are an explicit list of "
        "`(W, b)` pairs, the same layout in the NumPy reference and the PyTorch path. Hidden layers "
        "use silu, which is smooth: the physics residuals differentiate the velocity field in x and "
        "t, and a ReLU's kinks would make those derivatives jump. The example is a 2 → 4 → 1 network "
        "with PyTorch's default initialisation (`mlp_layers`), including a large input where silu's "
        "exact logistic matters.",
        [session("layers = mlp_layers(np.random.default_rng(0), d_in=2, hidden=4, depth=1, d_out=1)",
                 {"W0": layers[0][0], "b0": layers[0][1], "W1": layers[1][0], "b1": layers[1][1], "x": x},
                 "y = mlp(layers, x)", {"y": mlp(layers, x)})],
    )


SECTIONS = {"VG-ENC": encoding_section, "VG-MLP": mlp_section}
