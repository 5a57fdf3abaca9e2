"""Message definitions (.msg) and JSON schemas syncaudit reads and writes; shipped as package data."""
