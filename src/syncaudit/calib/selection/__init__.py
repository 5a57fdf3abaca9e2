"""Stage 1, selection: the LiDARs' scans read, still stops found and chosen, degenerate scenes refused."""
