#include "core/error.h"

#include "core/text.h"

namespace terrain {

const char* error_code_name(ErrorCode code) {
  static constexpr const char* kNames[] = {"not found",
                                           "truncated",
                                           "oversized",
                                           "dimension mismatch",
                                           "unknown type or format",
                                           "non-finite value",
                                           "missing or malformed field",
                                           "write failed",
                                           "corrupt",
                                           "checksum mismatch",
                                           "unsupported version",
                                           "invalid option"};
  return enum_name(code, kNames);
}

}  // namespace terrain
