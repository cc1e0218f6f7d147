"""Step 2: coarse (FPFH + RANSAC) and fine (ICP, GICP, the paper's PFH + SAC-IA) registration of
the after cloud onto the before cloud, column surfaces, georeferencing trust.
"""
