set terminal pngcairo size 900,360 font ",10" noenhanced
set output "batch_quality.png"
set multiplot layout 1,2 title "Batches of views, same number of views seen (--preset fast)"
set xlabel "views per step (--batch_views)"
set logscale x 2
set xtics (1,2,4)
set xrange [0.8:5]
set key center right
set ylabel "NC x100"
set yrange [95:98.5]
plot "batch_quality.dat" u 1:2 w lp pt 7 t "main (64 px torus)", "" u 1:4 w lp pt 5 t "fresh dented, seed 71", "" u 1:6 w lp pt 9 t "suzanne (256 px)"
set ylabel "aligned PSNR (dB)"
set yrange [23.5:26.5]
plot "batch_quality.dat" u 1:3 w lp pt 7 t "main", "" u 1:5 w lp pt 5 t "fresh dented", "" u 1:7 w lp pt 9 t "suzanne"
unset multiplot
