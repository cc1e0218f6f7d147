"""Step 3: bias compensation: the paper's plane offsets d_i and the stable-ground correction of the
difference.
"""
