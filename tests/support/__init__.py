"""Helpers shared by the tests (imported as `support.<module>`: conftest.py puts tests/ on
sys.path; tests/test_support.py keeps test files from importing conftest or each other).
Nothing here is part of the wideprint package.

- images: test planes, CMYK TIFFs on the device grid, the repository root
- server: the print server in process and as a process, the standalone emulator
- printing: a job on the in-process emulator, variant printer profiles, replay
- gui: the GUI tests' server and window
- background: long single-threaded computations run at the lowest priority
- marks: which tests are slow, system or gui
- cups, cutter, packaging: CUPS's conversions, a camera cutter, the installed tree
- printcut: a PDF with brand spots and CutContour lines; where cut paths and ink land
- private_cups, private_mdns: a private cupsd and `serve --ipp`; avahi in private namespaces
- ipp, cups_backend, web: ipptool against the Printer Application, the CUPS backend run as
  cupsd runs it, the web page in headless chromium
- corpus: hand-made BMPs and minimal headers, the hostile corpus of broken files
- rtl_encode: an HP RTL writer of the tests' own, independent of rip/rtl.py"""
