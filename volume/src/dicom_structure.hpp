#pragma once
/// @brief Private to the DICOM reader: the structural check a file passes before GDCM reads it.

#include <filesystem>

namespace caps::detail {

/// Walks the element headers of the DICOM file `file` (Part 10 with its meta group, or a bare
/// data set) and throws unless GDCM can read it without allocating more than the file holds or
/// aborting the process on one of its assertions: every declared length fits in what holds it
/// (the file, a sequence, an item); only standard VRs; undefined lengths only on sequences (SQ,
/// UN in CP-246 form) and on pixel data in an encapsulated transfer syntax; items and delimiters
/// only inside sequences; sequences at most 16 deep; each data set, item and sequence ends where
/// its length or delimiter says. Throws IoError naming the file, the fault and its byte offset;
/// InvalidInput for a deflated data set (transfer syntax 1.2.840.10008.1.2.1.99), which caps does
/// not read: GDCM would inflate it with no bound before anything could be checked. Reads only
/// element headers; linear in the number of elements.
void check_dicom_structure(const std::filesystem::path& file);

}  // namespace caps::detail
