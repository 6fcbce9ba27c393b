#pragma once
// Durable file replacement: write a temporary file in the target's directory, fsync it, rename it
// over the target, fsync the directory.  A power cut leaves either the old file, the whole new
// file, or (for a new name) no file -- never a half-written one.  The temporary is named
// ".<name>.tmp.<pid>.XXXXXX"; one left by a killed writer is removed by the next run that writes
// into the folder (io/staged_directory.hpp: remove_stale_temporaries).
#include <filesystem>
#include <string_view>

namespace errsep::io {

/// Writes `content` to `path` atomically and durably.  Throws std::runtime_error naming the path
/// and the cause (including "disk full" for ENOSPC); on failure the temporary file is removed and
/// any previous file at `path` is left untouched.  Not real-time safe.
void write_file_atomic(const std::filesystem::path& path, std::string_view content);

}  // namespace errsep::io
