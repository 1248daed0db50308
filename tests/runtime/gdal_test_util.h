// GDAL (Debian's gdal-bin) as an independent checker in tests: the toolchain itself stays GDAL-free.
#pragma once

#include <catch2/catch.hpp>
#include <cstdlib>
#include <string>

#include "io/io_test_util.h"
#include "shared_data.h"

namespace gdaltest {

// gdal-bin is installed by scripts/setup; without it a test fails in CI and is skipped elsewhere.
inline bool have_gdal() {
  if (std::system("command -v gdalinfo >/dev/null 2>&1 && command -v gdal_translate >/dev/null 2>&1 && "
                  "command -v gdalsrsinfo >/dev/null 2>&1") == 0)
    return true;
  if (testdata::in_ci()) FAIL("gdal-bin missing in CI (scripts/setup installs it)");
  WARN("gdal-bin not installed: GDAL interoperability test skipped");
  return false;
}

// Runs a GDAL command line, REQUIREs success, and returns its stdout and stderr.
inline std::string gdal(const iotest::TempDir& dir, const std::string& command) {
  const std::string out = dir.file("gdal.out");
  const int status = std::system((command + " >" + iotest::shell_quote(out) + " 2>&1").c_str());
  const auto bytes = iotest::read_file(out);
  const std::string text(bytes.begin(), bytes.end());
  INFO(command << "\n" << text);
  REQUIRE(status == 0);
  return text;
}

}  // namespace gdaltest
