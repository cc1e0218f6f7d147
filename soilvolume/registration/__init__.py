"""Step 2: coarse and fine registration of the after cloud onto the before, georeferencing trust."""
