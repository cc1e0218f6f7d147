"""Step 1 of the method: reading clouds (LAS/LAZ, COPC, VPC, PLY, text), one working CRS,
streaming, ground selection and the crop of the before cloud to the after cloud's GPS footprint.
"""
