// The project's one error type. Every library throws terrain::Error for a failure caused by its input
// (a file, a bitstream, a value read from a file, an option the data cannot honour), with a message
// that names the file or option and the problem. Violations of a function's documented preconditions
// by its caller are programming errors and throw std::logic_error (std::invalid_argument,
// std::out_of_range) instead. Codes say what went wrong, not how a program should exit: the tools map
// them to their documented exit statuses in one place (tools/common/cli.cpp, exit_status()).
#pragma once

#include <stdexcept>
#include <string>

namespace terrain {

enum class ErrorCode {
  NotFound,            // a file is missing, unreadable, or not a regular file
  Truncated,           // fewer bytes than the header or the dimensions need
  Oversized,           // more bytes than the dimensions need
  DimensionMismatch,   // dimensions cannot be derived, or disagree between file, header and options
  UnknownType,         // an unknown format, sample type or byte order (also: not a .pyr file)
  NonFinite,           // NaN or infinity where a finite value is needed
  MissingField,        // a header, sidecar or container field is missing, malformed or out of range
  WriteFailed,         // an output could not be created, written, synced or renamed
  CorruptData,         // contents inconsistent with their own description (bad bitstream, bad offsets)
  ChecksumMismatch,    // a stored checksum does not match the bytes it covers
  UnsupportedVersion,  // a format version this build does not read
  InvalidOption,       // an option or argument value the input cannot honour
};

// A short lower-case name of the code ("truncated", "checksum mismatch", ...), for messages and
// JSON reports. Never null.
const char* error_code_name(ErrorCode code);

class Error : public std::runtime_error {
 public:
  // message: the whole text shown to a user, naming the file (or option) and the problem.
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const { return code_; }

 private:
  ErrorCode code_;
};

}  // namespace terrain
