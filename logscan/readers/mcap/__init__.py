"""MCAP input and output: records, the scan, the CDR fast path, metadata, the reader and the writer."""

from logscan.readers.mcap.metadata import PROFILE_RECORD, TRUTH_RECORD, attach_logscan_records, read_mcap_metadata
from logscan.readers.mcap.reader import inspect_mcap, read_mcap
from logscan.readers.mcap.scan import iter_raw_messages
from logscan.readers.mcap.writer import TopicData, write_mcap

__all__ = [
    "PROFILE_RECORD",
    "TRUTH_RECORD",
    "TopicData",
    "attach_logscan_records",
    "inspect_mcap",
    "iter_raw_messages",
    "read_mcap",
    "read_mcap_metadata",
    "write_mcap",
]
