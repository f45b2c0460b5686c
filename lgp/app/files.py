"""The one atomic writer, for the application wing: it lives on the ground floor
(lgp/atomic.py), so that the analysis and every command line write through the
same code; see that module for what it promises (whole files or none, unique
temporary names, a full disk named, spreadsheet-safe CSV cells)."""
from lgp.atomic import (DiskFull, atomic_path, spreadsheet_safe, umask, write_bytes_atomic,  # noqa: F401
                        write_csv_atomic, write_json_atomic, write_text_atomic)
