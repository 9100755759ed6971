"""Pure MOOS formats: mission files, alog/slog/ylog/xlog/blog, naming and glob patterns.

Nothing here opens files, sockets or reads clocks: text and bytes in, objects out.
"""
