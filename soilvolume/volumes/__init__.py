"""Step 5: V = S_g * sum(H_after - H_before - d_i) in typed stages (:mod:`.compute`), holes, verdict."""
