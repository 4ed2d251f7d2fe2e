"""Writes the hand-made .zmx samples of tests/data/zmx (see README.md there).

Run from this folder: ``python make_handmade_samples.py``.  Zemax-style files of
published designs; every number is in README.md's sources.
"""

def surf(k, curv, disz, diam, glas=None, stop=False, typ="STANDARD", extra=""):
    s = f"SURF {k}\n"
    if stop:
        s += "  STOP\n"
    s += f"  TYPE {typ}\n  FIMP \n  CURV {curv!s} 0 0 0 0 \"\"\n  HIDE 0 0 0 0 0 0 0 0 0 0\n  MIRR 2 0\n"
    s += f"  DISZ {disz}\n"
    if glas:
        s += f"  GLAS {glas}\n"
    s += extra
    s += f"  DIAM {diam} 0 0 0 1 \"\"\n  MEMA {diam} 0 0 0 1 \"\"\n"
    s += "  POPS 0 0 0 0 0 0 0 0 1 1 1 1 0 0 0 0\n"
    return s

def header(name, unit, aperture):
    return (f"VERS 190513 80 123456\nMODE SEQ\nNAME {name}\nPFIL 0 0 0\nLANG 0\n"
            f"UNIT {unit} X W X CM MR CPMM\n{aperture}\nENVD 20 1 0\nGFAC 0 0\nGCAT SCHOTT\n"
            "RAIM 0 0 1 1 0 0 0 0 0 1\nPUSH 0 0 0 0 0 0\nSDMA 0 1 0\nFTYP 0 0 3 3 0 0 0\n"
            "ROPD 2\nPICB 1\n"
            "WAVM 1 0.48613270000000001 1\nWAVM 2 0.58756180000000002 1\nWAVM 3 0.65627250000000004 1\n"
            "PWAV 2\nPOLS 1 0 1 0 0 1 0\n")

TRAILER = "BLNK \nTOL TOFF   0   0              0              0   0 0 0 0\nMNUM 1 1\nMOFF   0   1 \"\" 0 0 0 1 1 0 0.0 \"\" 0\n"

def c(r):
    return repr(1.0 / r)

# Cooke triplet, f = 50 mm, F/5 (EPD 10), HFOV 20 deg: the Zemax sample design as given in
# Optiland's CookeTriplet; stop ON surface 4; glasses SK16 / F2 with catalogue nd, vd.
cooke = header("Cooke triplet f=50 F/5 HFOV 20 (Zemax sample design, as in Optiland CookeTriplet)",
               "MM", "ENPD 10")
cooke += "YFLN 0 14 20\nXFLN 0 0 0\n"
cooke += surf(0, "0.0", "INFINITY", "0")
cooke += surf(1, c(22.01359), "3.25896", "9.34", "SK16 0 0 1.62041 60.32 0 0 0 0 0 0 ")
cooke += surf(2, c(-435.76044), "6.00755", "8.88")
cooke += surf(3, c(-22.21328), "0.99997", "4.38", "F2 0 0 1.62004 36.37 0 0 0 0 0 0 ")
cooke += surf(4, c(20.29192), "4.75041", "3.8045529933742", stop=True)
cooke += surf(5, c(79.68360), "2.95208", "6.965", "SK16 0 0 1.62041 60.32 0 0 0 0 0 0 ")
cooke += surf(6, c(-18.39533), "42.20778", "7.335")
cooke += surf(7, "0.0", "0", "18.2")
cooke += TRAILER
# Zemax writes .zmx as UTF-16 LE with a byte-order mark and CRLF line ends.
open("cooke-triplet-50mm.zmx", "wb").write(
    b"\xff\xfe" + cooke.replace("\n", "\r\n").encode("utf-16-le"))

# Plano-convex singlet, Edmund Optics 49-847 (f = 25.4 mm, N-SF11), stop on the convex face.
singlet = header("Edmund 49-847 plano-convex f=25.4 N-SF11 (as in Optiland Edmund_49_847)",
                 "MM", "ENPD 25.4")
singlet += surf(0, "0.0", "INFINITY", "0")
singlet += surf(1, c(19.93), "7", "12.7", "N-SF11 0 0 1.78472 25.68 0 0 0 0 0 0 ", stop=True)
singlet += surf(2, "0.0", "21.48", "12.7")
singlet += surf(3, "0.0", "0", "1.0")
singlet += TRAILER
open("singlet-pcx-25mm.zmx", "w", newline="\n").write(singlet)

# Tessar f/4.5, HFOV 20.5 deg, M. Laikin, Lens Design 4th ed. (2007) p. 63 (as in Optiland
# TessarLens), in inches; a front dummy surface; K10 given as a model glass (___BLANK).
tessar = header("Tessar f/4.5 HFOV 20.5 (Laikin, Lens Design 4th ed. p. 63)", "IN", "FNUM 4.5 0")
tessar += surf(0, "0.0", "INFINITY", "0")
tessar += surf(1, "0.0", "0.5", "0.8")
tessar += surf(2, c(1.3329), "0.2791", "0.6528", "N-SK15 0 0 1.62299 58.12 0 0 0 0 0 0 ")
tessar += surf(3, c(-9.9754), "0.2054", "0.6112")
tessar += surf(4, c(-2.0917), "0.09", "0.4328", "F2 0 0 1.62004 36.37 0 0 0 0 0 0 ")
tessar += surf(5, c(1.2123), "0.0709", "0.3664")
tessar += surf(6, "0.0", "0.1534", "0.35739", stop=True)
tessar += surf(7, c(-7.5205), "0.09", "0.448", "___BLANK 1 0 1.50137 56.41 0 0 0 0 0 0 ")
tessar += surf(8, c(1.3010), "0.3389", "0.5348", "N-SK15 0 0 1.62299 58.12 0 0 0 0 0 0 ")
tessar += surf(9, c(-1.5218), "3.4025", "0.572")
tessar += surf(10, "0.0", "0", "1.5")
tessar += TRAILER
open("tessar-laikin-inch.zmx", "w", newline="\r\n").write(tessar)
