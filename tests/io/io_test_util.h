// Helpers for the io tests: a self-deleting temporary directory, byte-level file writing, and
// running a tool executable to capture its exit status and stderr.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "readers/heightmap.h"

namespace iotest {

class TempDir {
 public:
  TempDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "terrain-io-test-XXXXXX").string();
    std::vector<char> buf(pattern.begin(), pattern.end());
    buf.push_back('\0');
    if (!mkdtemp(buf.data())) throw std::runtime_error("mkdtemp failed");
    path_ = buf.data();
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

inline void write_file(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), std::streamsize(bytes.size()));
}

inline void write_file(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

inline std::vector<uint8_t> read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline std::string tool_path(const std::string& name) {
  if (const char* bin = std::getenv("TERRAIN_BIN")) return std::string(bin) + "/" + name;
  return std::string(TERRAIN_BINARY_DIR "/tools/") + name;
}

struct ToolResult {
  int status = -1;  // exit status, or -1 if it did not exit normally
  std::string err;  // captured stderr
  std::string out;  // captured stdout
};

inline std::string shell_quote(const std::string& s) {
  std::string q(1, '\'');
  for (char c : s) {
    if (c == '\'')
      q.append("'\\''");
    else
      q.push_back(c);
  }
  q.push_back('\'');
  return q;
}

struct Invocation {
  std::string tool;
  std::vector<std::string> args;
};

// Runs one tool invocation, capturing stdout/stderr into files inside `dir` named after `tag`.
inline ToolResult run_tool(const TempDir& dir, const Invocation& call, const std::string& tag = "tool") {
  std::string out_file = dir.file(tag + ".stdout"), err_file = dir.file(tag + ".stderr");
  std::string cmd = shell_quote(tool_path(call.tool));
  for (const auto& a : call.args) {
    cmd.push_back(' ');
    cmd.append(shell_quote(a));
  }
  cmd.append(" >").append(shell_quote(out_file)).append(" 2>").append(shell_quote(err_file));
  int raw = std::system(cmd.c_str());
  ToolResult r;
  if (raw != -1 && WIFEXITED(raw)) r.status = WEXITSTATUS(raw);
  auto e = read_file(err_file), o = read_file(out_file);
  r.err.assign(e.begin(), e.end());
  r.out.assign(o.begin(), o.end());
  return r;
}

// Runs the invocations concurrently, so that process start-up (and, for image inputs, loading the
// OpenImageIO plugin) overlaps. Results are in the order of `calls`.
inline std::vector<ToolResult> run_tools(const TempDir& dir, const std::vector<Invocation>& calls) {
  std::vector<ToolResult> results(calls.size());
  std::vector<std::thread> threads;
  for (size_t i = 0; i < calls.size(); ++i)
    threads.emplace_back([&, i] { results[i] = run_tool(dir, calls[i], "call" + std::to_string(i)); });
  for (auto& t : threads) t.join();
  return results;
}

// Sets an environment variable for the tools a test runs, restoring it afterwards so that later
// test cases in the same process are unaffected.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    setenv(name, value.c_str(), 1);
  }
  ~ScopedEnv() {
    if (old_)
      setenv(name_, old_->c_str(), 1);
    else
      unsetenv(name_);
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  const char* name_;
  std::optional<std::string> old_;
};

// Big-endian int16 tile bytes from a heightmap (voids written as -32768).
inline std::vector<uint8_t> hgt_bytes(const terrain::Heightmap& map) {
  std::vector<uint8_t> bytes;
  bytes.reserve(map.values.size() * 2);
  for (int64_t y = 0; y < map.height(); ++y)
    for (int64_t x = 0; x < map.width(); ++x) {
      auto v = uint16_t(int16_t(map.is_valid(x, y) ? map.at(x, y) : -32768));
      bytes.push_back(uint8_t(v >> 8));
      bytes.push_back(uint8_t(v & 0xff));
    }
  return bytes;
}

}  // namespace iotest
