//! Tests of the XML importer.
