"""The reports: the run table (defined once), the reproduction and its report.md, report.html,
the section beyond the paper and the seed spread."""
