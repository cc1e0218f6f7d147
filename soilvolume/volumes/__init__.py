"""Step 5: the DEM of difference and V = S_g * sum(H_after - H_before - d_i), as a chain of
typed stages (:mod:`.compute`): refill, correction, classification, interval, budgets; hole
filling in :mod:`.holes`; the quality verdict.
"""
