#pragma once
// Where a scan ran, in the machine's own coordinates, and which way its readings count: the
// configured facts that turn a separated straightness S(x) (x counted from the scan start, the
// sign of the sensor readings) into an error of the machine at machine positions, which is what a
// controller's compensation table is indexed by.
//
//   machine position of the input axis  p(x) = slide_start_mm + scan_direction * x
//   error of the output axis            e(p) = reading_sign * S(x)
//
// e is ISO 230-1's straightness error motion E<output><input> (e.g. EYX: the actual position of Y
// minus its commanded position while X is at p).  reading_sign = +1 says that a reading grows
// when the moving carriage goes towards +output relative to the artefact; it depends on how the
// sensor and the artefact are mounted, so it is written in the machine config once, not guessed.
#include <string>

namespace errsep::core {

struct MachineAxes {
  char input_axis = 'X';        ///< machine axis moved by the scan's slide (X, Y or Z)
  char output_axis = 'Y';       ///< machine axis the sensors read along (the compensated axis)
  double slide_start_mm = 0.0;  ///< machine position of the input axis at scan x = 0
  int scan_direction = 1;       ///< +1: x grows with the machine position; -1: it runs towards -
  int reading_sign = 1;  ///< +1: a reading grows when the carriage moves towards +output_axis

  /// Machine position of the input axis at scan coordinate x_mm.
  double machine_mm(double x_mm) const { return slide_start_mm + scan_direction * x_mm; }
  /// ISO 230-1 symbol of the straightness this describes, e.g. "EYX".
  std::string symbol() const;
  bool is_valid(std::string* why) const;
};

/// 'X', 'Y' or 'Z' for "X"/"x"/..., else 0.
char parse_linear_axis(const std::string& s);

}  // namespace errsep::core
