"""Statistics that compare settings from their runs' scores (README.md says what lives here)."""
