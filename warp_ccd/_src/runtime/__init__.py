"""What every stage stands on: arrays taken from anywhere (numpy, Warp, DLPack), device buffers with a
capacity and a counter, the counted frame (a CUDA graph and one read of counters), option checks."""
