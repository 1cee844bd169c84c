"""Files: atomic writes, OpenEXR with JSON metadata, storage codecs, atlases and PNGs."""
