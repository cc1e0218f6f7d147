"""Step 3: bias compensation: the paper's plane offsets d_i, the stable-ground correction."""
