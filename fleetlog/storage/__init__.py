"""The only file I/O: session writers and readers for plain, gzip and zstd logs."""
