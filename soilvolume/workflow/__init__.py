"""The method's orchestration: the estimate run step by step, and the other commands (DEM of one
cloud, registration only, volume between two DEMs).
"""
