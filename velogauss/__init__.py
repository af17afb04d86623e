"""velogauss: the application layer -- data, synthetic scenes, model, training,
evaluation, rendering, export and the `velogauss` command line, built on velogauss_fast."""
