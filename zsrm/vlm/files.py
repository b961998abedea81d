"""Moved to :mod:`zsrm.common.files`; this alias keeps old imports working (import from there)."""
from zsrm.common.files import (ZsrmFileError, atomic_path, check_writable, json_type, output_error,  # noqa: F401
                               read_json, write_json, write_text)
