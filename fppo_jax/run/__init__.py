"""A run from settings to outcome: train, sweep, the driver loop and its call-outs."""
