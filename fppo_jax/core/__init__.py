"""The pure, jitted core: what one training run computes (README.md says what lives here)."""
