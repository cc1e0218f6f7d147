"""The products: the method's steps composed for each command."""
