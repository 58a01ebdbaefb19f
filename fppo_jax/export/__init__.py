"""A trained policy taken elsewhere: ONNX and rendering."""
