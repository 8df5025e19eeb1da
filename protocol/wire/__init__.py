"""Fixed-width encodings: the strict reader of received bytes, integers and bit packing."""
