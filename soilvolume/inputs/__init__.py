"""Step 1 of the method: reading clouds, one working CRS, streaming, ground selection and the crop
of the before cloud to the after cloud's GPS footprint."""
