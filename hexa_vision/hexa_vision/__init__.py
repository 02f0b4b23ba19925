"""hexa_vision: camera, pose (detector + markers) and isolation nodes; the algorithms live in hexa.vision."""
