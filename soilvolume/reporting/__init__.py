"""Step 6: report.json and the self-contained report.html (figures drawn in numpy)."""
