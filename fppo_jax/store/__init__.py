"""What is written and read back: files, checkpoints, sweeps, metric logs, saved policies."""
