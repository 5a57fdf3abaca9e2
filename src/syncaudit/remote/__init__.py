"""Logs in object storage (s3://, gs://, az://, http(s)://) read through fsspec."""
