"""USD in and out: a stage read once into a scene and set to each time code, animations written.
``pxr`` (usd-core) is imported inside functions only."""
