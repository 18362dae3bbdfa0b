"""The canonical HDF5 reference format: schema, records, writer, reader, validator."""

from wristmimic.format.reader import Dataset, SequenceView, open_dataset
from wristmimic.format.records import HumanoidRecord, ObjectRecord, SequenceRecord
from wristmimic.format.schema import SCHEMA_VERSION
from wristmimic.format.writer import DatasetWriter

__all__ = [
    "SCHEMA_VERSION",
    "Dataset",
    "DatasetWriter",
    "HumanoidRecord",
    "ObjectRecord",
    "SequenceRecord",
    "SequenceView",
    "open_dataset",
]
