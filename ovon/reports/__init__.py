"""Reports over run folders: comparison tables, failure breakdowns, plots and episode videos."""
