"""Input sources of `moi identify`: trace and marker CSV files, videos and image folders."""
