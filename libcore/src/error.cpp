#include "core/error.h"

namespace terrain {

const char* error_code_name(ErrorCode code) {
  switch (code) {
    case ErrorCode::NotFound:
      return "not found";
    case ErrorCode::Truncated:
      return "truncated";
    case ErrorCode::Oversized:
      return "oversized";
    case ErrorCode::DimensionMismatch:
      return "dimension mismatch";
    case ErrorCode::UnknownType:
      return "unknown type or format";
    case ErrorCode::NonFinite:
      return "non-finite value";
    case ErrorCode::MissingField:
      return "missing or malformed field";
    case ErrorCode::WriteFailed:
      return "write failed";
    case ErrorCode::CorruptData:
      return "corrupt";
    case ErrorCode::ChecksumMismatch:
      return "checksum mismatch";
    case ErrorCode::UnsupportedVersion:
      return "unsupported version";
    case ErrorCode::InvalidOption:
      return "invalid option";
  }
  return "unknown error";
}

}  // namespace terrain
