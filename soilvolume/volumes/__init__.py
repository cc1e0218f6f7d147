"""Step 5: V = S_g * sum(H_after - H_before - d_i) as a chain of typed stages (:mod:`.compute`), hole
filling (:mod:`.holes`) and the quality verdict."""
