"""Step 5: the DEM of difference and V = S_g * sum(H_after - H_before - d_i): change areas,
cut/fill, uncertainty, zones, the quality verdict.
"""
