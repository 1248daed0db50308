// Stripe builds into part files, the journal that lets a killed build resume, and the assembly of
// the parts into one .pyr on rank 0.
//
// Part file (little endian): header "PYRPART1", u32 CRC-32C of the fingerprint, u32 stripe, u32
// stripes, u32 levels, u64 finest width; then one record per band the stripe owns, in the order
// the builder gives them (levels interleaved, each top to bottom): u32 "PREC", u32 level, u64 y0,
// u64 rows, f64 res_sq, f64 err_sq, u64 res_max, u64 err_max, u64 counted, u64 stream bytes, u64
// mask bytes (0: the rows have no void; else rows * width bits), u32 CRC-32C of the record's
// header and payload; then the stream and the mask bits. Trailer: u32 "PEND", u32 record count,
// u32 CRC-32C of the header's fingerprint CRC and the count. A part is complete when its trailer is
// there and its records chain up to it; the assembly checks every record's CRC.
#include "build/stripe_build.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>

#include "codec/crc32c.h"
#include "core/bytes.h"
#include "core/error.h"
#include "core/file.h"

namespace terrain::build {
namespace {

constexpr char kPartMagic[8] = {'P', 'Y', 'R', 'P', 'A', 'R', 'T', '1'};
constexpr uint32_t kRecordMagic = 0x43455250;   // "PREC"
constexpr uint32_t kTrailerMagic = 0x444e4550;  // "PEND"
constexpr size_t kHeaderBytes = 32, kRecordHeader = 84, kTrailerBytes = 12;

[[noreturn]] void write_failed(const std::string& path, const std::string& what) {
  throw Error(ErrorCode::WriteFailed, path + ": " + what + ": " + std::strerror(errno));
}

// Part k of K; k == K is the shared coarse levels' part (rank 0 writes it).
std::string part_path(const std::string& dir, int stripes, int k) {
  return dir + "/stripe-" + std::to_string(stripes) + "-" + (k == stripes ? "coarse" : std::to_string(k)) +
         ".part";
}

// The coarse levels' sink: keeps T^_k whole for the stripes' fine levels and hands the bands on.
class CoarseSink final : public PyramidSink {
 public:
  CoarseSink(PyramidSink& out, int level, GridSize size) : out_(out), level_(level), width_(size.width) {
    grid.assign(size_t(size.width * size.height), 0);
  }
  void begin(const PyramidHeader& h) override { out_.begin(h); }
  void band_figures(int l, int64_t y0, const BandFigures& f) override { out_.band_figures(l, y0, f); }
  void band(int l, int64_t y0, int64_t rows, std::vector<uint8_t>&& bytes) override {
    out_.band(l, y0, rows, std::move(bytes));
  }
  bool wants_reconstruction(int l) const override { return l == level_; }
  void reconstructed_rows(int, int64_t y0, int64_t rows, int64_t, const int32_t* data) override {
    std::copy(data, data + rows * width_, grid.begin() + y0 * width_);
  }
  std::vector<int32_t> grid;  // T^_k

 private:
  PyramidSink& out_;
  int level_;
  int64_t width_;
};

// Runs run(stripe) seeking past the rows above the stripe, and again reading them where a void
// fill turns out to need its carry from there (BuildStripe::seek_above): each stripe read its way
// down the input from row 0, which with four stripes was 7 % of the build's CPU (docs/scale.md).
template <class Run> BuildResult seeking(BuildStripe stripe, Run&& run) {
  stripe.seek_above = true;
  try {
    return run(stripe);
  } catch (const StripeRowsAboveNeeded&) {
    stripe.seek_above = false;
    return run(stripe);
  }
}

// Runs run(i) for i in [0, n) on `workers` threads (this one included), claimed in order; returns
// after all, rethrowing the first exception (items not yet started are then skipped).
template <class Run> void run_concurrently(int workers, size_t n, Run&& run) {
  std::atomic<size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex lock;
  const auto work = [&] {
    for (size_t i; !failed.load() && (i = next.fetch_add(1)) < n;) try {
        run(i);
      } catch (...) {
        const std::lock_guard<std::mutex> hold(lock);
        if (!error) error = std::current_exception();
        failed.store(true);
      }
  };
  std::vector<std::thread> threads;
  for (int w = 1; w < std::min<int>(workers, int(n)); ++w) threads.emplace_back(work);
  work();
  for (std::thread& t : threads) t.join();
  if (error) std::rethrow_exception(error);
}

// The shared coarse level k, with two or more stripes (-1: none, every stripe codes every level).
// The higher k, the shorter each stripe's cone of needed bands (they stop at level k + 1) but the
// more the coarse levels cost, and every process builds them: m - 2 for one process (levels 0..m-2
// are 1/12 of the samples, built once on all its threads), m - 4 for several (1/192 each). One
// process, one thread, 8192^2 Everest mirror, --step 2, T_{m-1} kept (user CPU, whole build 2.97 s):
// 4 / 16 stripes 3.25 / 3.88 s at m - 2, 3.33 / 4.37 s at m - 3, 3.39 / 4.68 s at m - 4. MPI on the
// 2-core VM, 16384^2 --lossless --threads 1: -np 2 8.72-9.53 s at m - 3 against 8.20-8.25 s at m - 4
// (8b251b7: 7.99-8.18 s), -np 4 (oversubscribed) 14.27 / 14.18 s of user CPU in all (8b251b7 14.33).
// T_k and T^_k are held whole (8 bytes a sample of level k): k comes down until they take at most an
// eighth of the memory budget.
int shared_level(const std::vector<GridSize>& sizes, int stripes, int processes, bool wanted,
                 int64_t budget) {
  const int m = int(sizes.size()) - 1;
  if (!wanted || stripes < 2 || m < 1) return -1;
  int k = std::max(0, m - (processes > 1 ? 4 : 2));
  const auto bytes = [&](int l) {
    return 8.0 * double(sizes[size_t(l)].width) * double(sizes[size_t(l)].height);
  };
  while (k > 0 && budget > 0 && bytes(k) > double(budget) / 8) --k;
  return k;
}

// The builder's output of one stripe, written to a temporary part and renamed when complete.
class PartWriter final : public PyramidSink {
 public:
  PartWriter(const std::string& path, uint32_t fingerprint, int k, int stripes, int64_t width)
      : path_(path), fingerprint_(fingerprint), width_(width) {
    fd_ = create_temp_beside(path, "", &temp_);
    uint8_t h[kHeaderBytes];
    std::memcpy(h, kPartMagic, 8);
    bytes::put_u32(h + 8, fingerprint);
    bytes::put_u32(h + 12, uint32_t(k));
    bytes::put_u32(h + 16, uint32_t(stripes));
    bytes::put_u32(h + 20, 0);  // levels: patched in at begin()
    bytes::put_u64(h + 24, uint64_t(width));
    buffer_.assign(h, h + kHeaderBytes);
    // A test hook: the process kills itself after this many bands (a killed build, for the resume test).
    if (const char* env = std::getenv("TERRAIN_TEST_KILL_AFTER_BANDS")) kill_after_ = std::atol(env);
  }
  ~PartWriter() override {
    if (fd_ >= 0) {
      ::close(fd_);
      ::unlink(temp_.c_str());
    }
  }
  void begin(const PyramidHeader& header) override {
    bytes::put_u32(buffer_.data() + 20, uint32_t(header.levels.size()));
  }
  void mask_rows(int64_t, int64_t rows, const uint8_t* valid) override {
    mask_.clear();
    const int64_t n = rows * width_;
    if (std::memchr(valid, 0, size_t(n)) == nullptr) return;  // no voids: no mask (memchr: vector speed)
    mask_.assign(size_t((n + 7) / 8), 0);
    for (int64_t i = 0; i < n; ++i)
      if (valid[i]) mask_[size_t(i / 8)] |= uint8_t(1u << (i % 8));
  }
  void band_figures(int, int64_t, const BandFigures& f) override { figures_ = f; }
  void band(int level, int64_t y0, int64_t rows, std::vector<uint8_t>&& data) override {
    uint8_t h[kRecordHeader];
    bytes::put_u32(h, kRecordMagic);
    bytes::put_u32(h + 4, uint32_t(level));
    bytes::put_u64(h + 8, uint64_t(y0));
    bytes::put_u64(h + 16, uint64_t(rows));
    bytes::put_f64(h + 24, figures_.res_sq);
    bytes::put_f64(h + 32, figures_.err_sq);
    bytes::put_u64(h + 40, uint64_t(figures_.res_max));
    bytes::put_u64(h + 48, uint64_t(figures_.err_max));
    bytes::put_u64(h + 56, uint64_t(figures_.counted));
    bytes::put_u64(h + 64, data.size());
    bytes::put_u64(h + 72, mask_.size());
    uint32_t crc = codec::crc32c(h, 80);
    crc = codec::crc32c(data.data(), data.size(), crc);
    crc = codec::crc32c(mask_.data(), mask_.size(), crc);
    bytes::put_u32(h + 80, crc);
    append(h, kRecordHeader);
    append(data.data(), data.size());
    append(mask_.data(), mask_.size());
    mask_.clear();
    ++records_;
    if (kill_after_ > 0 && ++bands_written_total() >= kill_after_) {
      flush();
      std::raise(SIGKILL);
    }
  }
  // Writes the trailer, syncs and renames the part into place.
  void finish() {
    uint8_t t[kTrailerBytes];
    bytes::put_u32(t, kTrailerMagic);
    bytes::put_u32(t + 4, uint32_t(records_));
    uint8_t c[8];
    bytes::put_u32(c, fingerprint_);
    bytes::put_u32(c + 4, uint32_t(records_));
    bytes::put_u32(t + 8, codec::crc32c(c, 8));
    append(t, kTrailerBytes);
    flush();
    if (::fsync(fd_) != 0) write_failed(temp_, "cannot sync");
    ::close(fd_);
    fd_ = -1;
    if (::rename(temp_.c_str(), path_.c_str()) != 0)
      write_failed(path_, "cannot rename " + temp_ + " onto it");
  }

 private:
  static std::atomic<int64_t>& bands_written_total() {
    static std::atomic<int64_t> n{0};
    return n;
  }
  void append(const uint8_t* p, size_t n) {
    buffer_.insert(buffer_.end(), p, p + n);
    if (buffer_.size() >= (size_t(1) << 20)) flush();
  }
  void flush() {
    size_t done = 0;
    while (done < buffer_.size()) {
      const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) write_failed(temp_, "cannot write");
      done += size_t(n);
    }
    buffer_.clear();
  }
  std::string path_, temp_;
  int fd_ = -1;
  uint32_t fingerprint_;
  int64_t width_;
  std::vector<uint8_t> buffer_, mask_;  // buffer_ starts with the header (begin() fills in the levels)
  BandFigures figures_;
  int64_t records_ = 0, kill_after_ = 0;
};

// A complete part's records, indexed for the assembly.
struct PartRecord {
  int level;
  int64_t y0, rows;
  BandFigures figures;
  uint64_t offset, size, mask_size;  // offset: of the record header
};

class PartReader {
 public:
  // Opens a part; returns false when it is missing or not complete and `strict` is false.
  bool open(const std::string& path, uint32_t fingerprint, int k, int stripes, int levels, int64_t width,
            bool strict) {
    path_ = path;
    records_.clear();
    if (fd_ >= 0) ::close(fd_), fd_ = -1;
    if (!std::filesystem::exists(path)) {
      if (strict) throw Error(ErrorCode::NotFound, path + ": part missing");
      return false;
    }
    uint64_t size = 0;
    fd_ = open_regular_file(path, &size);
    const auto bad = [&](const std::string& why) {
      if (strict)
        throw Error(ErrorCode::CorruptData, path + ": " + why + " (remove the directory to start over)");
      return false;
    };
    uint8_t h[kHeaderBytes];
    if (size < kHeaderBytes + kTrailerBytes || !read_at(h, kHeaderBytes, 0)) return bad("too short");
    if (std::memcmp(h, kPartMagic, 8) != 0 || bytes::get_u32(h + 8) != fingerprint ||
        bytes::get_u32(h + 12) != uint32_t(k) || bytes::get_u32(h + 16) != uint32_t(stripes) ||
        bytes::get_u32(h + 20) != uint32_t(levels) || bytes::get_u64(h + 24) != uint64_t(width))
      return bad("header does not match this build");
    uint64_t at = kHeaderBytes;
    const uint64_t end = size - kTrailerBytes;
    while (at < end) {
      uint8_t r[kRecordHeader];
      if (end - at < kRecordHeader || !read_at(r, kRecordHeader, at) || bytes::get_u32(r) != kRecordMagic)
        return bad("record at byte " + std::to_string(at) + " is damaged");
      PartRecord rec;
      rec.level = int(bytes::get_u32(r + 4));
      rec.y0 = int64_t(bytes::get_u64(r + 8));
      rec.rows = int64_t(bytes::get_u64(r + 16));
      rec.figures.res_sq = bytes::get_f64(r + 24);
      rec.figures.err_sq = bytes::get_f64(r + 32);
      rec.figures.res_max = int64_t(bytes::get_u64(r + 40));
      rec.figures.err_max = int64_t(bytes::get_u64(r + 48));
      rec.figures.counted = int64_t(bytes::get_u64(r + 56));
      rec.size = bytes::get_u64(r + 64);
      rec.mask_size = bytes::get_u64(r + 72);
      rec.offset = at;
      const uint64_t left = end - at - kRecordHeader;
      if (rec.level < 0 || rec.level >= levels || rec.size > left || rec.mask_size > left - rec.size)
        return bad("record at byte " + std::to_string(at) + " is damaged");
      records_.push_back(rec);
      at += kRecordHeader + rec.size + rec.mask_size;
    }
    uint8_t t[kTrailerBytes], c[8];
    bytes::put_u32(c, fingerprint);
    bytes::put_u32(c + 4, uint32_t(records_.size()));
    if (at != end || !read_at(t, kTrailerBytes, end) || bytes::get_u32(t) != kTrailerMagic ||
        bytes::get_u32(t + 4) != uint32_t(records_.size()) || bytes::get_u32(t + 8) != codec::crc32c(c, 8))
      return bad("trailer missing or damaged");
    return true;
  }
  ~PartReader() {
    if (fd_ >= 0) ::close(fd_);
  }
  const std::vector<PartRecord>& records() const { return records_; }
  // Whether every record's CRC holds (a resumed build codes a damaged part again).
  bool intact() const {
    std::vector<uint8_t> data, mask;
    try {
      for (const PartRecord& r : records_) payload(r, data, mask);
    } catch (const Error&) {
      return false;
    }
    return true;
  }
  // The record's mask bits alone, unchecked: rank 0 reads them for the output's mask while the
  // part's owner checks the whole record's CRC as it copies the stream (a bad one fails the build).
  void mask(const PartRecord& r, std::vector<uint8_t>& bits) const {
    bits.resize(r.mask_size);
    if (!read_at(bits.data(), r.mask_size, r.offset + kRecordHeader + r.size)) truncated(r);
  }
  // The record's stream and mask bits, its CRC checked.
  void payload(const PartRecord& r, std::vector<uint8_t>& data, std::vector<uint8_t>& bits) const {
    uint8_t h[kRecordHeader];
    data.resize(r.size);
    if (!read_at(h, kRecordHeader, r.offset) || !read_at(data.data(), r.size, r.offset + kRecordHeader))
      truncated(r);
    mask(r, bits);
    uint32_t crc = codec::crc32c(h, 80);
    crc = codec::crc32c(data.data(), data.size(), crc);
    crc = codec::crc32c(bits.data(), bits.size(), crc);
    if (crc != bytes::get_u32(h + 80))
      throw Error(ErrorCode::ChecksumMismatch,
                  path_ + ": record at byte " + std::to_string(r.offset) +
                      " fails its checksum (remove the directory to start over)");
  }

 private:
  [[noreturn]] void truncated(const PartRecord& r) const {
    throw Error(ErrorCode::Truncated, path_ + ": cannot read the record at byte " + std::to_string(r.offset));
  }
  bool read_at(uint8_t* p, size_t n, uint64_t at) const {
    while (n > 0) {
      const ssize_t got = ::pread(fd_, p, n, off_t(at));
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) return false;
      p += got, n -= size_t(got), at += uint64_t(got);
    }
    return true;
  }
  std::string path_;
  int fd_ = -1;
  std::vector<PartRecord> records_;
};

std::string read_text(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return f ? s.str() : std::string();
}

// Rank 0: a directory whose journal matches the fingerprint keeps its parts; any other starts over.
void prepare_directory(const StripeBuildOptions& so) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const std::string journal = so.directory + "/journal";
  if (fs::exists(so.directory, ec) && (!so.resume || read_text(journal) != so.fingerprint)) {
    // Only what a stripe build writes is removed: another directory of that name is not ours.
    if (!fs::is_directory(so.directory, ec) ||
        (fs::exists(journal, ec) == false && !fs::is_empty(so.directory, ec)))
      throw Error(ErrorCode::WriteFailed, so.directory + ": exists and is not a build journal directory");
    for (const auto& e : fs::directory_iterator(so.directory, ec)) {
      const std::string name = e.path().filename().string();
      if (name == "journal" || name.rfind("stripe-", 0) == 0 || name.rfind("journal.tmp", 0) == 0)
        fs::remove(e.path(), ec);
    }
  }
  // The temporaries of parts a killed build was writing.
  for (const auto& e : fs::directory_iterator(so.directory, ec))
    if (e.path().filename().string().find(".part.tmp.") != std::string::npos) fs::remove(e.path(), ec);
  fs::create_directories(so.directory, ec);
  if (ec) throw Error(ErrorCode::WriteFailed, so.directory + ": cannot create: " + ec.message());
  if (read_text(journal) == so.fingerprint) return;
  std::string temp;
  const int fd = create_temp_beside(journal, "", &temp);
  const bool ok =
      ::write(fd, so.fingerprint.data(), so.fingerprint.size()) == ssize_t(so.fingerprint.size()) &&
      ::fsync(fd) == 0;
  ::close(fd);
  if (!ok || ::rename(temp.c_str(), journal.c_str()) != 0) {
    ::unlink(temp.c_str());
    write_failed(journal, "cannot write the journal");
  }
}

}  // namespace

std::string stripe_directory(const std::string& output) { return output + ".build"; }

int read_journal_stripes(const std::string& directory, const std::string& base) {
  const std::string text = read_text(directory + "/journal");
  if (text.size() <= base.size() || text.compare(0, base.size(), base) != 0) return 0;
  const std::string rest = text.substr(base.size());
  if (rest.rfind("stripes ", 0) != 0) return 0;
  const int k = std::atoi(rest.c_str() + 8);
  return k > 0 && rest == "stripes " + std::to_string(k) + "\n" ? k : 0;
}

void remove_stripe_directory(const std::string& directory) {
  std::error_code ec;
  std::filesystem::remove_all(directory, ec);
}

namespace {

// Stripe boundaries in finest rows, multiples of the band height S (any split gives the same bytes).
// Where every stripe codes every level, each stripe edge costs both neighbours the D cascade and the
// coarse bands over its halo: measured on a 16384^2 input (m = 7) at 4 even stripes, the two end
// stripes took 3.6-3.7 s and the two interior ones 4.0-4.2 s (0.45 s an edge, about 4.5 x 2^m rows
// of a stripe's cost). So with three or more stripes the two end ones, which have one neighbour, get
// h = 4 x 2^m rows more than the others; an even split where that would leave a stripe without a
// band. With the coarse levels shared (`shared`) an edge costs a few dozen rows: an even split.
std::vector<int64_t> stripe_bounds(int64_t H, int64_t S, int K, int m, bool shared) {
  const int64_t bands = (H + S - 1) / S;
  std::vector<int64_t> even(size_t(K) + 1);
  for (int k = 0; k <= K; ++k) even[size_t(k)] = std::min(H, int64_t(k) * bands / K * S);
  if (K < 3 || shared) return even;
  const int64_t h = int64_t(4) << std::clamp(m, 0, 40);
  const double r = (double(H) - 2.0 * double(h)) / double(K);  // an interior stripe's rows
  if (r < double(S)) return even;
  std::vector<int64_t> b(size_t(K) + 1);
  b[0] = 0;
  b[size_t(K)] = H;
  for (int k = 1; k < K; ++k) {
    const int64_t y = std::llround((double(h) + double(k) * r) / double(S)) * S;
    b[size_t(k)] = std::clamp<int64_t>(y, b[size_t(k) - 1] + S, H - int64_t(K - k) * S);
  }
  return b;
}

}  // namespace

BuildResult build_stripes(const std::function<std::unique_ptr<BandReader>()>& open_input,
                          const BuildOptions& options, ResidualCoder& coder, const StripeBuildOptions& so,
                          const std::function<container::PyramidFileWriter&()>& open_output,
                          int* stripes_resumed) {
  SingleProcess alone;
  ProcessGroup& group = so.group ? *so.group : alone;
  const int rank = group.rank(), ranks = group.size();
  const GridInfo info = open_input()->info();
  const int64_t H = info.height, S = coder.band_rows();
  const int64_t bands = (H + S - 1) / S;
  const int K = int(std::clamp<int64_t>(so.stripes, 1, std::max<int64_t>(1, bands)));
  const uint32_t fp = codec::crc32c(so.fingerprint.data(), so.fingerprint.size());
  const std::vector<GridSize> level_sizes =
      pyramid_level_sizes({info.width, H}, options.level_count, options.min_coarsest_side);
  const int levels = int(level_sizes.size());
  const int split = shared_level(level_sizes, K, ranks, so.share_coarse_levels, options.memory_budget);
  const std::vector<int64_t> bounds = stripe_bounds(H, S, K, levels - 1, split >= 0);
  const auto stripe_rows = [&](int k) { return bounds[size_t(k)]; };

  // Set up by rank 0 before anyone looks at the directory.
  std::exception_ptr error;
  if (rank == 0) try {
      prepare_directory(so);
    } catch (...) {
      error = std::current_exception();
    }
  if (!group.all_true(!error)) {
    if (error) std::rethrow_exception(error);
    throw Error(ErrorCode::WriteFailed, so.directory + ": another process failed to set up the build");
  }

  // D is fitted by this process's first stripe and given to its later ones as a fixed filter (the
  // same taps, so the same coarse levels): the fit is a stripe's largest fixed cost.
  BuildResult result;
  bool have_result = false;
  BuildOptions stripe_options = options;
  int resumed = 0;
  // Where a striped build's time goes (the log): this process's stripes, the wait for the others,
  // rank 0's assembly of the output.
  using Clock = std::chrono::steady_clock;
  const auto seconds = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
  };
  const auto t_stripes = Clock::now();
  std::vector<std::string> stripe_lines;  // this process's stripes, for the log
  auto t_coded = t_stripes;
  const auto keep_filter = [&](BuildResult&& r) {
    if (have_result) return;
    result = std::move(r);
    have_result = true;
    stripe_options.use_fixed_filter = true;
    stripe_options.fixed_filter = result.header.filter;
  };
  // This process's stripes, and those a matching journal has complete.
  std::vector<int> mine, todo;
  for (int k = rank; k < K; k += ranks) mine.push_back(k);
  try {
    for (int k : mine) {
      PartReader existing;
      if (so.resume && existing.open(part_path(so.directory, K, k), fp, k, K, levels, info.width, false) &&
          existing.intact())
        ++resumed;
      else
        todo.push_back(k);
    }
  } catch (...) {
    error = std::current_exception();
  }
  // This process's stripes are built `concurrency` at a time, each on threads / concurrency threads
  // and an equal share of the memory budget (as many at once as the budget holds the fine-level
  // builders' minimum; the T_{m-1} rows pass 1 keeps come off the top): with the coarse levels
  // shared, a stripe on one thread scales as separate processes do, where the threads of one
  // streaming build wait on its serial parts (docs/scale.md).
  std::mutex result_lock;
  const int threads = std::max(1, options.threads);
  // T_k and T^_k, held whole while the stripes are built, and the T_{m-1} rows pass 1 keeps for pass
  // 2 (a quarter of the stripes' samples as int32) where the two fit half the budget: D's finest level
  // then runs once, at the price of fewer stripes at once.
  int64_t todo_rows = 0;
  for (int k : todo) todo_rows += stripe_rows(k + 1) - stripe_rows(k);
  const double shared_bytes =
      split >= 0 ? 8.0 * double(level_sizes[size_t(split)].width) * double(level_sizes[size_t(split)].height)
                 : 0.0;
  const double fine_bytes = double(todo_rows) * double(info.width);
  const bool keeps_fine_rows =
      split >= 0 && split < levels - 2 && !todo.empty() &&
      (options.memory_budget == 0 || shared_bytes + fine_bytes <= double(options.memory_budget) / 2);
  const double held_bytes = shared_bytes + (keeps_fine_rows ? fine_bytes : 0.0);
  int concurrency = int(std::clamp<size_t>(mine.size(), 1, size_t(threads)));
  const auto concurrent_options = [&](int c) {
    BuildOptions o = stripe_options;
    o.threads = std::max(1, threads / c);
    if (options.memory_budget > 0)
      // A fifth held back where several run at once: their threads' heaps keep freed blocks (16 stripes
      // of 16384^2 four at a time peaked at 1117 MiB under 1G with equal shares of the whole).
      o.memory_budget = std::max<int64_t>(
          1, int64_t((double(options.memory_budget) - held_bytes) / c * (c > 1 ? 0.8 : 1.0)));
    return o;
  };
  while (concurrency > 1) {
    BuildOptions o = concurrent_options(concurrency);
    if (options.memory_budget == 0) break;
    const int64_t budget = o.memory_budget;
    o.memory_budget = 0;
    if (plan_build_memory(info, o, S, true, split >= 0 ? split + 1 : 0).minimum_bytes <= budget) break;
    --concurrency;
  }
  if (concurrency > 1)
    stripe_lines.push_back("stripes built " + std::to_string(concurrency) + " at a time, " +
                           std::to_string(std::max(1, threads / concurrency)) + " thread(s) each");
  // Runs build(i, options) for i in [0, n), `concurrency` at a time; where D is fitted (not fixed),
  // item 0 first and alone, with all the threads, so that the others start with its filter fixed.
  const auto build_all = [&](size_t n, const std::function<void(size_t, const BuildOptions&)>& build) {
    size_t from = 0;
    if (!stripe_options.use_fixed_filter && n > 0) build(from++, stripe_options);
    const BuildOptions o = concurrent_options(concurrency);
    run_concurrently(concurrency, n - from, [&](size_t i) { build(from + i, o); });
  };

  // Shared coarse levels: every stripe's rows of T_k (pass 1), exchanged, then levels 0..k once.
  std::vector<int32_t> coarse_reconstruction;
  std::vector<StripeLevelRows> kept;  // per stripe: the T_{m-1} rows its first pass kept
  if (split >= 0) {
    bool coarse_done = true;
    if (rank == 0 && !error) {
      PartReader coarse;
      coarse_done = so.resume &&
                    coarse.open(part_path(so.directory, K, K), fp, K, K, levels, info.width, false) &&
                    coarse.intact();
    }
    if (!group.all_true(!error && todo.empty() && coarse_done)) {
      const GridSize sk = level_sizes[size_t(split)];
      std::vector<uint8_t> blob;
      const auto t_rows = Clock::now();
      kept.resize(size_t(K));
      std::vector<StripeLevelRows> made(mine.size());
      try {
        if (error) std::rethrow_exception(error);
        const auto make = [&](size_t i, const BuildOptions& o) {
          const int k = mine[i];
          // Only a stripe still to be coded needs its T_{m-1} rows (keeps_fine_rows above says where).
          const bool keep = keeps_fine_rows && std::find(todo.begin(), todo.end(), k) != todo.end();
          BuildResult r = seeking(BuildStripe{stripe_rows(k), stripe_rows(k + 1)}, [&](const BuildStripe& s) {
            auto reader = open_input();
            return build_stripe_level_rows(*reader, o, s, split, coder, made[i], keep);
          });
          const std::lock_guard<std::mutex> hold(result_lock);
          keep_filter(std::move(r));
        };
        build_all(mine.size(), make);
        for (size_t i = 0; i < mine.size(); ++i) {
          const int k = mine[i];
          StripeLevelRows& rows = made[i];
          const size_t at = blob.size();
          blob.resize(at + 16 + rows.rows.size() * 4);
          bytes::put_u64(blob.data() + at, uint64_t(rows.first_row));
          bytes::put_u64(blob.data() + at + 8, uint64_t(rows.rows.size()));
          std::memcpy(blob.data() + at + 16, rows.rows.data(), rows.rows.size() * 4);
          rows.rows = {};
          kept[size_t(k)] = std::move(rows);
        }
      } catch (...) {
        error = std::current_exception();
      }
      if (!group.all_true(!error)) {
        if (error) std::rethrow_exception(error);
        throw Error(ErrorCode::WriteFailed, so.directory + ": another process failed");
      }
      const double rows_seconds = seconds(t_rows, Clock::now());
      const auto t_coarse = Clock::now();
      // T_k put together: the stripes' shares tile the level (checked: a gap would be a logic error).
      std::vector<int32_t> tk(size_t(sk.width * sk.height));
      int64_t covered = 0;
      for (const std::vector<uint8_t>& b : group.all_gather(std::move(blob)))
        for (size_t at = 0; at < b.size();) {
          const int64_t first = int64_t(bytes::get_u64(b.data() + at));
          const uint64_t n = bytes::get_u64(b.data() + at + 8);
          if (n % uint64_t(sk.width) != 0 || first < 0 ||
              uint64_t(first) * uint64_t(sk.width) + n > tk.size() || b.size() - at - 16 < n * 4)
            throw std::logic_error("stripe build: level rows out of place");
          std::memcpy(tk.data() + first * sk.width, b.data() + at + 16, n * 4);
          covered += int64_t(n);
          at += 16 + n * 4;
        }
      if (covered != sk.width * sk.height) throw std::logic_error("stripe build: level rows missing");
      // Levels 0..k: on every process with stripes to code (they need T^_k) and on rank 0, which
      // writes them into the coarse part.
      if (!todo.empty() || rank == 0) try {
          if (!have_result) {
            CountingSink none;
            auto reader = open_input();
            keep_filter(build_pyramid_stripe(*reader, options, BuildStripe{0, 0}, coder, none));
          }
          CountingSink discard;
          std::unique_ptr<PartWriter> part;
          if (rank == 0)
            part = std::make_unique<PartWriter>(part_path(so.directory, K, K), fp, K, K, info.width);
          CoarseSink sink(part ? static_cast<PyramidSink&>(*part) : discard, split, sk);
          build_pyramid_coarse_levels(info, stripe_options, split, tk, coder, sink);
          if (part) part->finish();
          coarse_reconstruction = std::move(sink.grid);
        } catch (...) {
          error = std::current_exception();
        }
      std::ostringstream line;
      line.precision(3);
      line << "shared coarse levels 0.." << split << ": this process's rows of level " << split << " made in "
           << rows_seconds << " s, levels 0.." << split << " coded in " << seconds(t_coarse, Clock::now())
           << " s";
      stripe_lines.push_back(line.str());
    }
  }
  try {
    if (error) std::rethrow_exception(error);
    int done = 0;
    const auto code = [&](size_t i, const BuildOptions& o) {
      const int k = todo[i];
      const auto t_stripe = Clock::now();
      BuildResult r = seeking(BuildStripe{stripe_rows(k), stripe_rows(k + 1)}, [&](const BuildStripe& s) {
        PartWriter part(part_path(so.directory, K, k), fp, k, K, info.width);
        auto reader = open_input();
        BuildResult built = split >= 0 ? build_pyramid_stripe_fine_levels(
                                             *reader, o, s, split, coarse_reconstruction, coder, part,
                                             k < int(kept.size()) ? &kept[size_t(k)] : nullptr)
                                       : build_pyramid_stripe(*reader, o, s, coder, part);
        part.finish();
        return built;
      });
      if (k < int(kept.size())) kept[size_t(k)] = {};
      // Per stripe, for the balance between stripes (an interior one carries two halos).
      std::ostringstream line;
      line.precision(3);
      line << "stripe " << k << " of " << K << ": rows " << stripe_rows(k) << "-" << stripe_rows(k + 1)
           << " coded in " << seconds(t_stripe, Clock::now()) << " s";
      const std::lock_guard<std::mutex> hold(result_lock);
      stripe_lines.push_back(line.str());
      keep_filter(std::move(r));
      if (so.progress) so.progress(double(++done) / double(std::max<size_t>(1, todo.size())));
    };
    build_all(todo.size(), code);
  } catch (...) {
    error = std::current_exception();
  }
  t_coded = Clock::now();
  if (!group.all_true(!error)) {
    if (error) std::rethrow_exception(error);
    throw Error(ErrorCode::WriteFailed, so.directory +
                                            ": another process failed; completed stripes are kept "
                                            "for a resumed build");
  }
  if (stripes_resumed) *stripes_resumed = resumed;
  const auto t_assembly = Clock::now();

  // The assembly. Rank 0 lays the output out from the parts' record indexes (each band's stream goes
  // where a one-process build puts it), writes the band tables, mask and figures, and hands every
  // process the places of its own parts' streams; each process copies those in (threads share its
  // parts) and returns their CRCs, which rank 0 combines into the level CRCs. Rank 0 alone copying
  // every part was the one serial stage after the ranks' work (docs/scale.md "The decomposition").
  const int sources = K + (split >= 0 ? 1 : 0);  // the stripes' parts, then the coarse levels' part
  const auto owner = [&](int source) { return source == K ? 0 : source % ranks; };
  container::PyramidFileWriter* writer = nullptr;
  std::vector<LevelFigures> figures(static_cast<size_t>(levels));
  std::vector<std::vector<std::pair<int, size_t>>> level_records(static_cast<size_t>(levels));
  std::vector<std::vector<uint64_t>> record_sizes(static_cast<size_t>(sources));
  int64_t voids = 0;
  // Rank 0's plan for every process: 1, the temporary path, then per part its record count and each
  // record's destination and stream size (an owner that finds another size stops: no overlaps).
  std::vector<uint8_t> plan;
  if (rank == 0) try {
      // The header and D (the same for every stripe); a resumed rank 0 that coded nothing fits D again.
      if (!have_result) {
        CountingSink none;
        auto reader = open_input();
        result = build_pyramid_stripe(*reader, options, BuildStripe{0, 0}, coder, none);
      }
      writer = &open_output();
      writer->begin(result.header);
      std::vector<std::unique_ptr<PartReader>> parts;
      for (int source = 0; source < sources; ++source) {
        parts.push_back(std::make_unique<PartReader>());
        parts.back()->open(part_path(so.directory, K, source), fp, source, K, levels, info.width, true);
      }
      std::vector<std::vector<uint64_t>> destination(static_cast<size_t>(sources));
      for (int source = 0; source < sources; ++source) {
        destination[size_t(source)].assign(parts[size_t(source)]->records().size(), 0);
        for (const PartRecord& r : parts[size_t(source)]->records())
          record_sizes[size_t(source)].push_back(r.size);
      }
      std::vector<uint8_t> bits, valid;
      const int64_t W = info.width;
      for (int l = 0; l < levels; ++l) {
        const int64_t level_height = result.header.levels[size_t(l)].height;
        std::vector<container::PyramidFileWriter::PlacedBand> placed;
        int64_t next_row = 0;
        // Levels 0..split come from the coarse part, the others from the stripes' parts in order.
        for (int k = 0; k < K; ++k) {
          if (l <= split && k > 0) break;
          const int source = l <= split ? K : k;
          const PartReader& part = *parts[size_t(source)];
          const std::string where = part_path(so.directory, K, source) + ": record at byte ";
          for (size_t i = 0; i < part.records().size(); ++i) {
            const PartRecord& r = part.records()[i];
            if (r.level != l) continue;
            if (r.y0 != next_row || r.rows < 1 || r.rows > level_height - r.y0)
              throw Error(ErrorCode::CorruptData, where + std::to_string(r.offset) + " has rows " +
                                                      std::to_string(r.y0) + "+" + std::to_string(r.rows) +
                                                      " where level " + std::to_string(l) +
                                                      " continues at row " + std::to_string(next_row));
            next_row += r.rows;
            placed.push_back({r.rows, r.size});
            level_records[size_t(l)].push_back({source, i});
            figures[size_t(l)].add(r.figures, r.size);
            if (l != levels - 1) continue;
            if (r.mask_size == 0) {
              // No voids: one row of ones handed over row by row, not a band of them written each time.
              valid.assign(size_t(W), 1);
              for (int64_t y = r.y0; y < r.y0 + r.rows; ++y) writer->mask_rows(y, 1, valid.data());
              continue;
            }
            if (r.mask_size != uint64_t((r.rows * W + 7) / 8))
              throw Error(ErrorCode::CorruptData,
                          where + std::to_string(r.offset) + " has a mask of the wrong size");
            part.mask(r, bits);
            valid.resize(size_t(r.rows * W));
            for (int64_t n = 0; n < r.rows * W; ++n) valid[size_t(n)] = (bits[size_t(n / 8)] >> (n % 8)) & 1;
            voids += int64_t(std::count(valid.begin(), valid.end(), uint8_t(0)));
            writer->mask_rows(r.y0, r.rows, valid.data());
          }
        }
        if (next_row != level_height)
          throw Error(ErrorCode::CorruptData, so.directory + ": the parts' bands of level " +
                                                  std::to_string(l) + " cover " + std::to_string(next_row) +
                                                  " of " + std::to_string(level_height) + " rows");
        uint64_t at = writer->place_level(l, placed);
        for (size_t b = 0; b < placed.size(); ++b) {
          const auto [source, i] = level_records[size_t(l)][b];
          destination[size_t(source)][i] = at;
          at += placed[b].size;
        }
      }
      const std::string& temp = writer->temp_path();
      plan.push_back(1);
      plan.resize(5 + temp.size());
      bytes::put_u32(plan.data() + 1, uint32_t(temp.size()));
      std::memcpy(plan.data() + 5, temp.data(), temp.size());
      for (int source = 0; source < sources; ++source) {
        const std::vector<uint64_t>& d = destination[size_t(source)];
        const size_t at = plan.size();
        plan.resize(at + 8 + 16 * d.size());
        bytes::put_u64(plan.data() + at, d.size());
        for (size_t i = 0; i < d.size(); ++i) {
          bytes::put_u64(plan.data() + at + 8 + 16 * i, d[i]);
          bytes::put_u64(plan.data() + at + 16 + 16 * i, record_sizes[size_t(source)][i]);
        }
      }
    } catch (...) {
      error = std::current_exception();
      plan.clear();
    }
  const std::vector<uint8_t> layout = std::move(group.all_gather(std::move(plan))[0]);
  if (layout.empty()) {
    if (error) std::rethrow_exception(error);
    throw Error(ErrorCode::WriteFailed, so.directory + ": process 0 failed to lay out the output");
  }

  // This process's parts: each record's stream, its CRC checked, written at its place.
  std::vector<int> own;
  for (int source = 0; source < sources; ++source)
    if (owner(source) == rank) own.push_back(source);
  std::vector<std::vector<uint32_t>> stream_crcs(own.size());
  try {
    const std::string temp(reinterpret_cast<const char*>(layout.data() + 5),
                           bytes::get_u32(layout.data() + 1));
    // Where each part's records start in the plan.
    std::vector<size_t> places(static_cast<size_t>(sources));
    for (size_t at = 5 + temp.size(), source = 0; source < size_t(sources); ++source) {
      places[source] = at + 8;
      at += 8 + 16 * bytes::get_u64(layout.data() + at);
    }
    // A test hook: this rank's copy fails (scripts/check-striped-build: no output, the parts kept).
    if (const char* env = std::getenv("TERRAIN_TEST_FAIL_COPY"); env && std::atoi(env) == rank)
      throw Error(ErrorCode::WriteFailed, temp + ": the copy failed (TERRAIN_TEST_FAIL_COPY)");
    const int fd = ::open(temp.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd < 0) write_failed(temp, "cannot open the output process 0 created");
    try {
      run_concurrently(threads, own.size(), [&](size_t n) {
        const int source = own[n];
        PartReader part;
        part.open(part_path(so.directory, K, source), fp, source, K, levels, info.width, true);
        const uint64_t count = bytes::get_u64(layout.data() + places[size_t(source)] - 8);
        if (count != part.records().size())
          throw Error(ErrorCode::CorruptData,
                      part_path(so.directory, K, source) + ": changed during the assembly");
        std::vector<uint8_t> data, bits;
        for (size_t i = 0; i < part.records().size(); ++i) {
          part.payload(part.records()[i], data, bits);
          const uint8_t* place = layout.data() + places[size_t(source)] + 16 * i;
          if (data.size() != bytes::get_u64(place + 8))
            throw Error(ErrorCode::CorruptData,
                        part_path(so.directory, K, source) + ": changed during the assembly");
          stream_crcs[n].push_back(codec::crc32c(data.data(), data.size()));
          uint64_t at = bytes::get_u64(place);
          for (size_t done = 0; done < data.size();) {
            const ssize_t w = ::pwrite(fd, data.data() + done, data.size() - done, off_t(at));
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) write_failed(temp, "cannot write");
            done += size_t(w), at += uint64_t(w);
          }
        }
      });
    } catch (...) {
      ::close(fd);
      throw;
    }
    if (::close(fd) != 0) write_failed(temp, "cannot close");
  } catch (...) {
    error = std::current_exception();
  }
  std::vector<uint8_t> checksums(1, error ? 0 : 1);
  for (size_t n = 0; n < own.size() && !error; ++n) {
    const size_t at = checksums.size();
    checksums.resize(at + 8 + 4 * stream_crcs[n].size());
    bytes::put_u32(checksums.data() + at, uint32_t(own[n]));
    bytes::put_u32(checksums.data() + at + 4, uint32_t(stream_crcs[n].size()));
    for (size_t i = 0; i < stream_crcs[n].size(); ++i)
      bytes::put_u32(checksums.data() + at + 8 + 4 * i, stream_crcs[n][i]);
  }
  const std::vector<std::vector<uint8_t>> copied = group.all_gather(std::move(checksums));
  for (const std::vector<uint8_t>& c : copied)
    if (c.empty() || c[0] != 1) {
      if (error) std::rethrow_exception(error);
      throw Error(ErrorCode::WriteFailed,
                  so.directory + ": another process failed to copy its parts into the output");
    }
  if (rank != 0) return result;

  // The level CRCs: the streams' CRCs combined in band order.
  std::vector<std::vector<uint32_t>> crc_of(static_cast<size_t>(sources));
  for (const std::vector<uint8_t>& c : copied)
    for (size_t at = 1; at < c.size();) {
      const uint32_t source = bytes::get_u32(c.data() + at), n = bytes::get_u32(c.data() + at + 4);
      if (source >= uint32_t(sources) || n != record_sizes[source].size() ||
          c.size() - at - 8 < 4 * size_t(n))
        throw std::logic_error("stripe build: stream checksums out of place");
      for (uint32_t i = 0; i < n; ++i) crc_of[source].push_back(bytes::get_u32(c.data() + at + 8 + 4 * i));
      at += 8 + 4 * size_t(n);
    }
  for (int l = 0; l < levels; ++l) {
    uint32_t crc = 0;
    for (const auto& [source, i] : level_records[size_t(l)])
      crc = codec::crc32c_combine(crc, crc_of[size_t(source)].at(i), record_sizes[size_t(source)][i]);
    writer->set_bands_crc(l, crc);
  }
  for (int l = 0; l < levels; ++l)
    result.levels[size_t(l)] = figures[size_t(l)].stats(result.header.levels[size_t(l)]);
  result.void_count = voids;
  std::ostringstream timing;
  timing.precision(3);
  timing << "; process 0 coded its stripes in " << seconds(t_stripes, t_coded) << " s, waited "
         << seconds(t_coded, t_assembly) << " s for the others, assembled the output in "
         << seconds(t_assembly, Clock::now()) << " s";
  result.log.insert(result.log.end(), stripe_lines.begin(), stripe_lines.end());
  result.log.push_back("stripes: " + std::to_string(K) + " over " + std::to_string(ranks) + " process" +
                       (ranks > 1 ? "es" : "") +
                       (resumed ? ", " + std::to_string(resumed) + " resumed" : "") + timing.str());
  return result;
}

}  // namespace terrain::build
