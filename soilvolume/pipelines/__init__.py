"""PDAL pipelines: JSON built from the options, users' pipelines loaded and confined, and the
embedded stages that run them without PDAL.
"""
