"""The only package that imports zenoh: session options, publish/subscribe/query helpers."""
