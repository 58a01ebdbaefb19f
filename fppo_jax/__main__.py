from fppo_jax.cli import entry_point

entry_point()
