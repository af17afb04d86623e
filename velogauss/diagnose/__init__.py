"""Diagnostics: where a trained run's motion error comes from, read against a generated scene's
ground truth (benchmarks/FIDELITY.md uses them). They time nothing, so they are not benchmarks.

`centre`: the learned velocity, spin and acceleration at each moving body's centre against the
truth; `visibility`: the velocity error split by whether a training camera sees the surface;
`slip`: how far each body's Gaussians turn against the body and slip off their material.
Run them as `velogauss diagnose centre|visibility|slip RUN...` (`commands`).
"""
