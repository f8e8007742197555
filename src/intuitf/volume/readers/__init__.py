"""One module per file format. Each exposes ``read(request) -> RawArray``."""
