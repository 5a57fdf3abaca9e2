"""Stage 5, validation: the estimates judged on the data (map consistency) and the result built."""
