// Editing a compressed pyramid in place (issue 20): brushes and patches change the finest level in a
// region; the change is carried to every coarser level through D, and the closed-loop residuals of
// exactly the libcodec tiles it reaches (U's and the tiles' own halo included) are re-coded with the
// file's own step / max error. Untouched tiles keep their bytes, even inside a re-coded band (their
// payloads are copied verbatim into the band's new stream); untouched bands keep their offsets.
// commit() appends the new band streams, level band maps and index after the file's end and then
// switches the superblock (docs/format.md, "Editing (2.2)"): a crash at any point leaves the
// previous version readable. compact() rewrites the file without dead bytes.
//
// What an edit is measured against. Given the heightmap the file was built from (set_source), the
// edits apply to it and every level's target is the builder's own T_l of the edited heightmap: the
// re-coded tiles then get exactly the residual a rebuild from the edited heightmap codes, so the
// edited file decodes like that rebuild and keeps the file's error guarantees against it. Without a
// source the editor has only the file: the new level l is T^_l (decoded) + Delta_l, Delta_finest the
// edit in level units and Delta_l = round(D(Delta_{l+1})); re-coded tiles meet the file's step / max
// error against that target, which itself is T^_l's error away from the edited input, plus the
// rounding of Delta_l (so about twice the bound there: measured 5 m at --max-error 2 on N46W122).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/rect.h"
#include "readers/heightmap.h"
#include "runtime/edit_overlay.h"

namespace terrain::edit {

// The viewer's in-memory edits and the file's share one set of shapes (names:
// runtime::edit_shape_name, runtime::parse_edit_shape; profile: runtime::edit_profile).
using BrushShape = runtime::EditShape;

// Adds height * profile(r / radius) metres to every finest-level sample within `radius` samples of
// (x, y) (column, row of the finest level; fractional allowed): cone 1 - r, smooth (1 - r^2)^2, flat 1.
struct Brush {
  double x = 0, y = 0, radius = 1, height = 0;
  BrushShape shape = BrushShape::Smooth;
};

// Blends a heightmap into the finest level: sample (x + i, y + j) becomes
// (1 - blend) * old + blend * heights[j * width + i] (metres; NaN = leave the sample alone).
struct Patch {
  int64_t x = 0, y = 0;  // finest-level position of the patch's sample (0, 0); may hang over the edges
  int64_t width = 0, height = 0;
  std::vector<float> heights;
  double blend = 1;  // 0..1
};

struct LevelEditStats {
  int64_t bands_recoded = 0;       // bands whose stream was rebuilt (appended)
  int64_t tiles_recoded = 0;       // libcodec tiles coded afresh
  int64_t tiles_kept = 0;          // tiles of rebuilt bands whose payload bytes were copied verbatim
  double max_abs_delta_units = 0;  // largest |Delta_l| in level units
  // Bounding box (level samples) of where T^_l changed: what a viewer's clipmap must reload
  // (empty when nothing changed at this level).
  Rect changed;
};

struct EditStats {
  std::vector<LevelEditStats> levels;  // coarsest first
  uint64_t bytes_appended = 0;         // by this commit (0 when nothing changed)
  uint64_t dead_bytes = 0;             // of the file after the commit
  uint64_t file_bytes = 0;
  uint64_t generation = 0;  // edit generation after the commit (0: never edited)
  double seconds = 0;
  bool changed = false;  // false: the edits rounded to nothing, the file is untouched
};

// For tests of crash safety: where commit() stops as if the process died there (the file keeps
// what was written up to that point, nothing is cleaned up).
enum class CrashPoint { None, AfterBlobs, AfterIndex, TornSuperblock };

class PyramidEditor {
 public:
  // Opens `path` for editing (PyramidFile::open's validation). Throws Error as PyramidFile::open
  // (naming the file), Error(WriteFailed) when the file is not writable.
  static std::unique_ptr<PyramidEditor> open(const std::string& path);
  ~PyramidEditor();

  // Queue an edit (applied in order at commit). Throws std::invalid_argument naming the problem
  // for a non-finite field, radius <= 0, a brush or patch that does not touch the grid, blend
  // outside [0, 1] or a patch whose size does not match its heights.
  void apply(const Brush& brush);
  void apply(const Patch& patch);
  // The heightmap the file was built from (see above); read whole, kept for the editor's life, and
  // its pyramid computed twice per commit (memory about 3x the grid in int32). Throws Error naming
  // the file (unreadable), std::invalid_argument when its size or level unit differs from the file's.
  void set_source(const std::string& heightmap_path, const ReadOptions& read_options = {});

  // Re-codes what the queued edits reach and commits atomically (fsync ordering: new bytes, index
  // and tail superblock, fsync, superblock, fsync). Throws Error(WriteFailed) on I/O failure (the
  // previous version stays), Error(InvalidOption) when an edit drives a sample or residual beyond
  // libcodec's range (nothing is written then). Clears the queue. Not thread-safe.
  EditStats commit(CrashPoint crash = CrashPoint::None);

  const std::string& path() const;
  // The source heightmap as the committed edits left it (set_source), or nullptr without one.
  const Heightmap* source() const;

 private:
  struct Impl;
  explicit PyramidEditor(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

struct CompactStats {
  uint64_t bytes_before = 0, bytes_after = 0;
};

// Rewrites `path` without dead bytes (a temporary beside it, renamed over it): every level blob
// becomes one contiguous 2.1-style band blob, so the result is what pyramid-build would lay out
// for the same streams. Decodes identically. Throws Error as PyramidFile::open / WriteFailed, and,
// before writing anything, Error(ChecksumMismatch) or Error(CorruptData) naming the level and band
// record when a level blob or a band stream it would copy fails its CRC or does not open (the new
// blobs' fresh CRCs would otherwise hide the damage from the container's check).
CompactStats compact(const std::string& path);

}  // namespace terrain::edit
