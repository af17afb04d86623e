"""Training: the loop, density control, optimiser schedules, checkpoints."""
